"""One ride session for both edges (the ROS node and the embedded replay): what decides
the advice and the engine built from it (`config`), samples in and advice out on the
stamp clock (`ride_session`) to sinks (`sinks`: MCAP log, Rerun, a publish callback);
`replay` reads and paces a ride log into it."""

import lazy_loader

# Public names load on first use, from `__init__.pyi` (why: itt_planner/__init__.py).
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
