"""Stage 3, the optimal control problems (CasADi): the mesh over the course (`mesh`), the
transcription of the dynamics (`transcription`, compiled by `codegen`), the simple bounds
C11-C14 of both problems (`bounds`), the initial guess (`guess`), the solver seam
(`solver`: `NlpSolver`, its option sets, `SolveResult` and the `PlanStatus` enum), the
full-course problem (`course_settings`, `course_nlp`, `course_problem`) and the
receding-horizon one (`horizon_settings`, `horizon_window`, `horizon`), the `Plan` and
its cut to a horizon (`plan`, `horizon_cut`), its independent verification (`verify`),
the plan cache (`cache`), the analysis of plans on a course (`analysis`) and the 1D plan
on the shortest line within the road (`line_plan`)."""

import lazy_loader

# Public names load on first use, from `__init__.pyi` (why: itt_planner/__init__.py).
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
