"""itt-planner: race support for cycling individual time trials.

The ROS-free core: course geometry, rider models, the pacing-and-cornering optimal
control problems (CasADi), state estimation, the pacing engine, ride logs, Rerun
logging and the CLI. See docs in README.md and the physics in model.md.

Importing it sets `OPENBLAS_NUM_THREADS` to 1 unless the environment sets it: CasADi's
bundled OpenBLAS (IPOPT's and MUMPS's dense kernels) otherwise starts a thread per core
for blocks too small to share, and those threads spin. The Zwift Bologna 3D plan: 202
iterations either way, the same plan, 82.3 s CPU (user + system) and 55.3 s wall with
the default threads, 49.3 s and 52.4 s with one (bench/RESULTS.md, 2026-12-03, lead,
third session). IPOPT's CPU budgets count every thread's time, so the spinning also
used up the solves' budgets (`OcpSettings.budget`) without progress. It must be set
before the library loads (IPOPT's plugin is loaded at the first solver built).
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import lazy_loader

# Each public name loads on first use from the module `__init__.pyi` imports it from
# (lazy_loader reads the stub's imports; type checkers read the stub as the package): a
# process that needs one module no longer imports every stage of the package with it.
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
