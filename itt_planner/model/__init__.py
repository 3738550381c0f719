"""Stage 2, rider and physics: the rider's parameters (`rider`), the weather and grip
(`conditions`), the W' balance model (`wprime`), the rider's state (`state`), the CasADi
spatial dynamics of model.md E1-E9 (`dynamics`, 3D, 1D and steady-lean 3D), the numeric
parameter vector and road data they take (`params`) and the steady-state speeds of the
power balance (`steady`)."""

import lazy_loader

# Each public name loads on first use from the module `__init__.pyi` imports it from
# (lazy_loader reads the stub's imports; type checkers read the stub as the package): a
# process that needs one module no longer imports every stage of the package with it.
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
