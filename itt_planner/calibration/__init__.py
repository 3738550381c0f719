"""Calibrate a rider from ride files, and validate the models and plans against rides.

Stage of the data path: recorded rides -> rider parameters (`calibrate`) -> the same rides
replayed through the models and the plan (`validate`). Estimator notes (equations,
assumptions, refusals) are in this package's README.md.
"""

import lazy_loader

# Each public name loads on first use from the module `__init__.pyi` imports it from
# (lazy_loader reads the stub's imports; type checkers read the stub as the package): a
# process that needs one module no longer imports every stage of the package with it.
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
