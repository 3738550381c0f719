"""Stage 4, the live loop: input samples (`samples`), state estimation (`estimate`, with
map matching in `map_match`), the W' balance and the CP in use (`wprime_balance`), CP
refits (`cp_monitor`), the pacing engine (`engine`: samples in, `Advice` out, clocked by
message stamps) with the plan in force (`plan_in_force`), the horizon's solves
(`horizon_step`) and re-solves of the rest of the course (`course_replan`), the shaping
of advice a rider can follow (`advice_shaping`) and the engine's health (`health`).

Nothing here imports ride logs, ROS or Rerun."""

import lazy_loader

# Public names load on first use, from `__init__.pyi` (why: itt_planner/__init__.py).
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
