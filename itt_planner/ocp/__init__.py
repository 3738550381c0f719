"""Stage 3, the optimal control problems (CasADi): the mesh over the course (`mesh`), the
transcription of the dynamics (`transcription`, compiled by `codegen`), the simple bounds
C11-C14 of both problems (`bounds`), the initial guess (`guess`), the solver seam
(`solver`: `NlpSolver`, its option sets, `SolveResult` and the `PlanStatus` enum), the
full-course problem (`course_settings`, `course_nlp`, `course_problem`) and the
receding-horizon one (`horizon_settings`, `horizon_window`, `horizon`), the `Plan` and
its cut to a horizon (`plan`, `horizon_cut`), its independent verification (`verify`),
the plan cache (`cache`), the analysis of plans on a course (`analysis`) and the 1D plan
on the shortest line within the road (`line_plan`)."""

from itt_planner.ocp.cache import load_or_solve
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.horizon import HorizonPlanner
from itt_planner.ocp.horizon_settings import HorizonSettings, HorizonSolution
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import NlpSolver, PlanStatus, SolveResult
from itt_planner.ocp.verify import Verification, verify_plan

__all__ = ["HorizonPlanner", "HorizonSettings", "HorizonSolution", "NlpSolver", "OcpSettings",
           "Plan", "PlanStatus", "SolveResult", "Start", "Verification", "load_or_solve",
           "solve_plan", "verify_plan"]
