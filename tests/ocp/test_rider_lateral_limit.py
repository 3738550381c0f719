"""The full-course 3D plan of a rider with a cornering limit below the grip (issue 18:
both models converging on any course, every plan verified).

The hairpin test course with 600 m straights and a rider limited to 4 m/s^2 ended in
Infeasible_Problem_Detected after 524 iterations: the first run converged, its launch
failed the verification (as every 3D plan's launch on this course does), and the
re-solve on a mesh built afresh, from the plan interpolated onto it, went astray. The
re-solve now splits the plan's own intervals and resumes from its primal-dual point.
"""

from __future__ import annotations

import numpy as np
from support.courses import hairpin

from itt_planner.model.conditions import GRAVITY_MPS2
from itt_planner.model.rider import Rider
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.solver import PlanStatus

#: Lateral acceleration beyond the rider's limit the checks allow (m/s^2): C16 is a hard
#: constraint of the full-course OCP, met to IPOPT's tolerance at the nodes.
_AY_TOL_MPS2 = 0.01
#: Lean beyond the steady lean of the limit (rad): the roll mode (E4-E5) is dynamic, so
#: the lean may lead or trail the steady `atan(a_y / g)` a little through the corner.
_LEAN_TOL_RAD = 0.02


def test_3d_plan_of_a_timid_rider_converges_verified_within_its_limit() -> None:
    limit = 4.0
    course = hairpin(straight_m=600.0)
    plan = solve_plan(course, Rider(name="timid", max_lateral_accel_mps2=limit), model="3d")
    attempts = plan.meta["attempts"]
    assert plan.converged, (plan.status, plan.solver_status, attempts)
    assert plan.meta["success"] and plan.meta["verification"]["verified"], plan.meta
    # The limit holds everywhere and is used through the hairpin (it binds, not grip).
    ay = np.abs(plan.ay_mps2)
    assert ay.max() <= limit + _AY_TOL_MPS2
    assert ay.max() > 0.95 * limit
    assert np.abs(plan.phi_rad).max() <= np.arctan(limit / GRAVITY_MPS2) + _LEAN_TOL_RAD
    # Corner speed: a_y = v^2 / R, and a 180 deg turn within the road (centre radius
    # 12 m, 4 m half-widths) has somewhere a radius no larger than its outer edge's.
    corner = course.corners[0]
    inside = (plan.s_m >= corner.entry_s_m) & (plan.s_m <= corner.exit_s_m)
    assert plan.v_mps[inside].min() <= np.sqrt(limit * (12.0 + 4.0))
    # A refinement after the launch's failed verification, if any, resumed from the
    # converged plan instead of a fresh start that went astray.
    assert all(a["outcome"] == PlanStatus.CONVERGED for a in attempts), attempts
