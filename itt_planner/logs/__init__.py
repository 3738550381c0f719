"""Stage 5, ride logs: MCAP ride logs in the ROS 2 profile (`ridelog`: the format and
reading, `ridelog_writer`: writing) and the import of ride files (FIT/GPX/TCX/CSV) into
them (`ride_import`)."""

import lazy_loader

# Each public name loads on first use from the module `__init__.pyi` imports it from
# (lazy_loader reads the stub's imports; type checkers read the stub as the package): a
# process that needs one module no longer imports every stage of the package with it.
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
