"""Stage 3, the optimal control problems (CasADi): the mesh over the course (`mesh`), the
transcription of the dynamics (`transcription`, compiled by `codegen`), the initial guess
(`guess`), the solver seam (`solver`: option sets and the `PlanStatus` enum), the
full-course problem (`course_problem`) and the receding-horizon one (`horizon`), the
`Plan` and its cut to a horizon (`plan`, `horizon_cut`), its independent verification
(`verify`) and the plan cache (`cache`)."""

from itt_planner.ocp.cache import load_or_solve
from itt_planner.ocp.course_problem import OcpSettings, Start, solve_plan
from itt_planner.ocp.horizon import HorizonPlanner, HorizonSettings, HorizonSolution
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus
from itt_planner.ocp.verify import Verification, verify_plan

__all__ = ["HorizonPlanner", "HorizonSettings", "HorizonSolution", "OcpSettings", "Plan",
           "PlanStatus", "Start", "Verification", "load_or_solve", "solve_plan", "verify_plan"]
