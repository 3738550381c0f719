"""The simple bounds of both OCPs, written once: C11-C14 and the speed range per node.

The full-course problem (`course_nlp`) and the receding horizon (`horizon`) bound the
same states the same way; what differs is passed in: the node positions, the initial
state the first node is fixed at, the speed cap (the horizon adds the plan's corner
speeds, `horizon_window.corner_speed_cap`) and the W' the finish must keep (C12, the
full-course problem's `e_final_min`). A state a model does not have is skipped (`phi`
exists in the full 3D model only, the lateral states not in the 1D model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import SpatialModel
from itt_planner.model.rider import Rider
from itt_planner.model.steady import speed_bound_mps
from itt_planner.ocp.transcription import Layout

#: Lowest speed the NLP allows (keeps 1/s_dot finite), m/s.
V_MIN_MPS = 0.5
#: Bounds on the normalised rates u (model.md C13/C14 note: loose, for robustness).
U_DELTA_MAX = 20.0
U_W_MAX = 50.0
#: |bound| of the normalised commands W_n (C13) and delta_n (C14).
_COMMAND_MAX = 1.0
#: Loose bounds (rad) on the relative heading and the lean: they keep trial points of
#: the solver in the range where the model is meaningful and are not active at a
#: solution before its last node (grip, C16, bounds the lean to ~atan(mu_y) = 0.79 rad
#: on a dry road; the last node is held to that: `simple_bounds`).
_ALPHA_MAX_RAD = 1.0
_PHI_MAX_RAD = 1.2
_U_MAX = {"u_delta": U_DELTA_MAX, "u_w": U_W_MAX}


@dataclass(frozen=True)
class Bounds:
    """Simple bounds per node (states, `nx x N+1`) and per interval (controls, `nu x N`).

    The first node is fixed: `lbx[:, 0] == ubx[:, 0]` is the initial state, clipped into
    the other bounds (a rider measured off the road starts on its edge).
    """

    lbx: np.ndarray
    ubx: np.ndarray
    lbu: np.ndarray
    ubu: np.ndarray

    @property
    def x0(self) -> np.ndarray:
        """The (clipped) initial state."""
        return self.lbx[:, 0]

    def decision(self, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) bounds of the whole decision vector of `layout`: slacks of the
        softened constraints (if any) are >= 0."""
        n, ns = layout.n_intervals, layout.ns
        return (layout.join(self.lbx, self.lbu, np.zeros((ns, n)), 0.0),
                layout.join(self.ubx, self.ubu, np.full((ns, n), np.inf), np.inf))


def speed_limit_mps(course: Course, nodes: np.ndarray, rider: Rider, conditions: Conditions,
                    v0_mps: float) -> float:
    """Physics' upper speed bound over the stretch of `nodes` (`model.speed_bound_mps` on
    the steepest descent there, issue 18): no physical ride gets faster, so it only keeps
    integration artefacts out."""
    inside = (course.s_m >= nodes[0] - course.ds_m) & (course.s_m <= nodes[-1] + course.ds_m)
    steepest = float(np.tan(np.min(course.beta_rad[inside], initial=0.0)))
    return speed_bound_mps(rider, conditions, steepest, start_mps=v0_mps)


def simple_bounds(model: SpatialModel, course: Course, nodes: np.ndarray, x0: np.ndarray, *,
                  margin_m: float, v_max_mps: float | np.ndarray,
                  finish_mu_y: float | None = None, e_final_min: float = 0.0) -> Bounds:
    """C11 (road edges less `margin_m`), C12 (0 <= E_n <= 1, and >= `e_final_min` at
    the last node), C13/C14 (|W_n|, |delta_n| <= 1, the rates u within `_U_MAX`),
    `V_MIN_MPS <= v <= v_max_mps` (per node or one value) and the loose angle bounds;
    the first node fixed at `x0` clipped into them.

    Where the last node is the finish (`finish_mu_y` given: the grip there), its lean is
    within the grip's steady lean, atan(`finish_mu_y`), and not changing: model.md
    leaves the end state free, and a plan whose finish is in a bend crossed the line
    falling (the loose bound, 69 deg, at 220 deg/s), as nothing after the line pays for
    it. The full-course problem gives it, and so do its windows on a long course
    (`course_windows`: a window's end lies in the overlap the next one replaces); a
    horizon window's end is tied to the plan by its soft terminal condition instead."""
    n = len(nodes)
    lbx, ubx = np.full((model.nx, n), -np.inf), np.full((model.nx, n), np.inf)

    def bound(state: str, lower: float | np.ndarray, upper: float | np.ndarray) -> None:
        if state in model.states:
            lbx[model.index(state)], ubx[model.index(state)] = lower, upper

    bound("n", -(course.at("width_right_m", nodes) - margin_m),  # C11
          course.at("width_left_m", nodes) - margin_m)
    bound("alpha", -_ALPHA_MAX_RAD, _ALPHA_MAX_RAD)
    bound("phi", -_PHI_MAX_RAD, _PHI_MAX_RAD)
    bound("v", V_MIN_MPS, v_max_mps)
    bound("w_n", -_COMMAND_MAX, _COMMAND_MAX)  # C13
    bound("delta_n", -_COMMAND_MAX, _COMMAND_MAX)  # C14
    bound("e_n", 0.0, 1.0)  # C12
    lbx[model.index("e_n"), -1] = e_final_min
    if finish_mu_y is not None and "phi" in model.states:
        lean = math.atan(finish_mu_y)
        lbx[model.index("phi"), -1], ubx[model.index("phi"), -1] = -lean, lean
        lbx[model.index("phi_dot"), -1] = ubx[model.index("phi_dot"), -1] = 0.0
    lbx[:, 0] = ubx[:, 0] = np.clip(x0, lbx[:, 0], ubx[:, 0])
    u_max = np.array([_U_MAX[name] for name in model.controls])[:, None]
    return Bounds(lbx, ubx, np.repeat(-u_max, n - 1, axis=1), np.repeat(u_max, n - 1, axis=1))
