"""The 1D plan on the shortest line within the road (`course.racing_line`).

The 1D model (model.md section 6) ignores the corners, so its time-optimal path is the
shortest one within the road less the C11 edge margin. `solve_plan_on_line` solves the 1D
OCP on the course along that line (`racing_line.line_course`: its length, the road's
altitude over it, its heading for the wind) and hands back the plan on the road's arc
length, like any plan of the course: `s_m` on the centre line, `n_m` and `alpha_rad` the
line's, `t_s` and every other array as solved. The plan's verification (in `solve_plan`)
replayed it on the line's course, where it was solved; `meta["line"]` says so, with the
line's length.

Why: on the centre line the 1D rode a longer course than the 3D plan, which takes its
own line on the road's width: St John's 1D 3746.18 s against 3D 3732.81 s (+0.36 %), with
the 3D line 0.38 % shorter, worth 13.8 s of the 13.4 s (bench/RESULTS.md, 2026-12-02).

`solve_rest_on_line`: the OCP of the rest of the course from a rider's state on the
line a given plan rides (its own n(s), `racing_line.offset_course`), with the 1D model
that knows the line's corners (`LINE_MODEL`, `model.dynamics.build_1d_line`: C15 and C16
at the lateral acceleration v^2 kappa of the line): the live engine's cheap re-solve on
the line of the 3D plan in force (`live.course_replan`), warm from the previous such
re-solve's primal-dual point (on the line's arc length, as its nodes are). Why that
model: the plain 1D ignores the corners (model.md section 6); on the Zwift Bologna ride
its re-solves of the technical first 8 km rode the 3D line's hairpins at up to 3.8 g,
9-17 s "faster" than the 3D re-solves, and 12 of 13 were refused (bench/RESULTS.md,
2026-12-02). `line_corners` stays as the guard: it gives a plan the lateral
acceleration the line's curvature asks at its speed (on the nodes' scale, as the OCP:
`verify.node_curvature`) and says where it is not rideable (C16's friction ellipse,
C15's pedalling lean, model.md section 4, at the steady lean of that acceleration).
`solve_plan_on_line(corners=True)` solves the shortest line with that model too.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.course.racing_line import RacingLine, line_course
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import steady_lean_rad
from itt_planner.model.params import lateral_limit_mps2
from itt_planner.model.rider import Rider
from itt_planner.ocp.course_nlp import PrimalDual
from itt_planner.ocp.course_problem import solve_plan, solve_plan_point
from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.verify import node_curvature

#: The model of the 1D plans on a line that know its corners (`build_1d_line`).
LINE_MODEL = "1dline"

def solve_plan_on_line(course: Course, rider: Rider, conditions: Conditions = Conditions(),
                       settings: OcpSettings = OcpSettings(), *, corners: bool = False
                       ) -> Plan:
    """The 1D plan of `course` on its shortest line (`settings.margin_m` from the edges),
    on the road's arc length (module doc). `corners`: the 1D model that knows the
    line's corners ("1dline", `build_1d_line`) instead of the plain 1D baseline.
    Statuses and errors as `solve_plan`."""
    line = line_course(course, settings.margin_m)
    model = LINE_MODEL if corners else "1d"
    return onto_road(solve_plan(line.course, rider, conditions, settings, model=model), line,
                     "shortest", rider)


def solve_rest_on_line(line: RacingLine, rider: Rider, conditions: Conditions,
                       settings: OcpSettings, *, guess: Plan, start: Start,
                       warm: PrimalDual | None = None) -> tuple[Plan, PrimalDual | None]:
    """The `LINE_MODEL` plan of the rest of `line.road` from `start` (road's arc length),
    solved on the line's course, on the road's arc length like `solve_plan_on_line`'s,
    `meta["line"]["kind"]` "plan". `guess`: a plan on the road's arc length (e.g. the
    plan in force). `warm`: the point a previous such re-solve on the SAME line returned
    (its nodes are on the line's arc length). Returns the plan and, if it converged, its
    primal-dual point (on the line's arc length). Statuses and errors as `solve_plan`."""
    on_line = Start(s_m=float(line.line_s(start.s_m)), state=dict(start.state))
    guess_on_line = dataclasses.replace(guess, s_m=line.line_s(guess.s_m))
    plan, point = solve_plan_point(line.course, rider, conditions, settings, model=LINE_MODEL,
                                   guess=guess_on_line, start=on_line, warm=warm)
    road = onto_road(plan, line, "plan", rider)
    if "start" in road.meta:  # where the rider was, on the road
        road.meta["start"] = {**road.meta["start"], "s_m": start.s_m, "line_s_m": on_line.s_m}
    return road, point


#: Slack on C15 and C16 in `line_corners` (1D plans ridden at the limit on a straight
#: are exactly at C16's longitudinal bound; the steady lean is a model of its own).
_CORNER_TOL = 0.02


def line_corners(plan: Plan, line: RacingLine, rider: Rider, conditions: Conditions
                 ) -> tuple[Plan, str]:
    """A 1D plan on `line` (`solve_rest_on_line`) with the lateral acceleration its speed
    asks on the line (`ay_mps2` = v^2 kappa_line, signed like the curvature, on the
    nodes' scale: `verify.node_curvature`) and the
    friction ellipse C16 with it (`friction_use`, the lateral term against
    `lateral_limit_mps2`); and why it is not rideable ("" if it is): C16 above 1, or
    pedalling beyond C15 (`W_n <= 1 - (phi / phi_pedal)^2`) at the steady lean
    phi = atan(a_y / g) (model.md section 4), each within `_CORNER_TOL`."""
    kappa = node_curvature(line.course, line.line_s(plan.s_m))
    ay = plan.v_mps ** 2 * kappa
    lon = plan.ax_mps2 / (conditions.mu_x * GRAVITY_MPS2)
    use = np.hypot(lon, ay / lateral_limit_mps2(rider, conditions))
    lean = np.abs(steady_lean_rad(ay))
    pedal = np.where(lean < rider.pedal_lean_max_rad,
                     1 - (lean / rider.pedal_lean_max_rad) ** 2, 0.0)
    out = dataclasses.replace(plan, ay_mps2=ay, friction_use=use)
    if np.max(use) > 1 + _CORNER_TOL:
        i = int(np.argmax(use))
        return out, (f"C16: friction use {use[i]:.2f} at s = {plan.s_m[i]:.0f} m "
                     f"({plan.v_mps[i]:.1f} m/s, lateral {ay[i]:.1f} m/s^2)")
    over = plan.w_n - pedal
    if np.max(over) > _CORNER_TOL:
        i = int(np.argmax(over))
        return out, (f"C15: pedalling (W_n {plan.w_n[i]:.2f}) at a lean of "
                     f"{np.degrees(lean[i]):.0f} deg at s = {plan.s_m[i]:.0f} m")
    return out, ""


def onto_road(plan: Plan, line: RacingLine, kind: str, rider: Rider) -> Plan:
    """A plan solved on `line.course`, on the road's arc length, with the line's offset
    and heading (and without the primal-dual point of its NLP, which is the line's). A
    plan of the model that knows the corners ("1dline") gets the lean and steering of
    the steady turn on the line (`steady_lean_rad` of its `ay_mps2`, tan(delta) = L
    kappa_line): what a 3D re-solve from it takes as its guess (`guess.plan_guess`)."""
    s_road = line.road_s(plan.s_m)
    n = np.interp(s_road, line.road.s_m, line.n_m)
    alpha = np.interp(s_road, line.road.s_m, line.alpha_rad)
    if plan.model == LINE_MODEL:
        kappa = node_curvature(line.course, plan.s_m)
        plan = dataclasses.replace(
            plan, phi_rad=np.asarray(steady_lean_rad(plan.ay_mps2)),
            delta_n=np.arctan(rider.wheelbase_m * kappa) / rider.steer_max_rad)
    meta = {**plan.meta, "line": {"kind": kind, "course": line.course.name,
                                  "length_m": line.course.length_m,
                                  "length_ratio": line.length_ratio}}
    # The NLP point is that of the line's course: no re-solve of the road starts from it.
    return dataclasses.replace(plan, s_m=s_road, n_m=n, alpha_rad=alpha, meta=meta,
                               point_w=None, point_lam_x=None, point_lam_g=None)
