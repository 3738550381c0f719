"""Type stub of `itt_planner.ocp`: its public names, loaded lazily by `__init__.py`."""

from .cache import load_or_solve
from .course_problem import solve_plan
from .course_settings import OcpSettings, Start
from .horizon import HorizonPlanner
from .horizon_settings import HorizonSettings, HorizonSolution
from .plan import Plan
from .solver import NlpSolver, PlanStatus, SolveResult
from .verify import Verification, verify_plan

__all__ = ["HorizonPlanner", "HorizonSettings", "HorizonSolution", "NlpSolver", "OcpSettings",
           "Plan", "PlanStatus", "SolveResult", "Start", "Verification", "load_or_solve",
           "solve_plan", "verify_plan"]
