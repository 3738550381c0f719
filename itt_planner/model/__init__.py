"""Stage 2, rider and physics: the rider's parameters (`rider`), the weather and grip
(`conditions`), the W' balance model (`wprime`), the rider's state (`state`), the CasADi
spatial dynamics of model.md E1-E9 (`dynamics`, 3D, 1D and steady-lean 3D), the numeric
parameter vector and road data they take (`params`) and the steady-state speeds of the
power balance (`steady`)."""

import lazy_loader

# Public names load on first use, from `__init__.pyi` (why: itt_planner/__init__.py).
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
