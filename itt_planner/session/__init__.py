"""One ride session for both edges (the ROS node and the embedded replay): what decides
the advice and the engine built from it (`config`), samples in and advice out on the
stamp clock (`ride_session`) to sinks (`sinks`: MCAP log, Rerun, a publish callback);
`replay` reads and paces a ride log into it."""

import lazy_loader

# Each public name loads on first use from the module `__init__.pyi` imports it from
# (lazy_loader reads the stub's imports; type checkers read the stub as the package): a
# process that needs one module no longer imports every stage of the package with it.
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
