"""Calibrate a rider from ride files, and validate the models and plans against rides.

Stage of the data path: recorded rides -> rider parameters (`calibrate`) -> the same rides
replayed through the models and the plan (`validate`). Estimator notes (equations,
assumptions, refusals) are in this package's README.md.
"""

import lazy_loader

# Public names load on first use, from `__init__.pyi` (why: itt_planner/__init__.py).
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
