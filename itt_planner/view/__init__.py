"""Stage 6, what people look at: a ride logged to Rerun and the static HTML/PNG report.

    rerun_paths      the timelines and entity paths of a ride recording, named once
    rerun_scene      what is logged once: course, road, profile, plan curves and line
    rerun_log        `RideRecorder`: samples, estimate, advice, belief, diagnostics
    rerun_blueprint  the default layout of the viewer
    rerun_sink       where a recording goes (file, viewer, server, none)
    ride_report      a replayed ride read back from its MCAP log
    report           the static HTML/PNG report of a plan or a ride
    report_sections  extra sections of the static report (calibrated rider, validation)
"""

import lazy_loader

# Public names load on first use, from `__init__.pyi` (why: itt_planner/__init__.py).
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
