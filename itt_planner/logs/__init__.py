"""Stage 5, ride logs: MCAP ride logs in the ROS 2 profile (`ridelog`: the format and
reading, `ridelog_writer`: writing) and the import of ride files (FIT/GPX/TCX/CSV) into
them (`ride_import`)."""

import lazy_loader

# Public names load on first use, from `__init__.pyi` (why: itt_planner/__init__.py).
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
