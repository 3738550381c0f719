"""The `Plan`: the solved optimal trajectory over a course, and its file format.

Arrays are over the arc-length grid `s_m` of the OCP nodes, in SI units. The 1D model
(model.md section 6) fills the lateral arrays with zeros. Saved as one `.plan.npz` file
(arrays + a JSON header with the solver figures and what the plan was computed for).

A plan may carry the primal-dual point of the NLP it solves (`POINT_ARRAYS`, on its own
nodes): a re-solve of the rest of the course from that plan then starts warm from it
(`course_nlp.PrimalDual`, `live.course_replan.plan_point`). They are saved in the same
file when present; a file without them (older ones, or a plan whose solve kept no point)
loads with them None, and its first re-solve starts from the primal point alone.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from itt_planner.errors import IttError

PLAN_SUFFIX = ".plan.npz"
_FORMAT = "itt-planner-plan"

#: Arrays of a plan, all of the length of `s_m`.
PLAN_ARRAYS = (
    "s_m", "t_s", "n_m", "alpha_rad", "phi_rad", "phi_dot_radps", "v_mps", "w_n", "delta_n",
    "e_n", "u_delta", "u_w", "power_w", "w_prime_j", "ax_mps2", "ay_mps2", "friction_use",
    "costate_v_s_per_mps",
)
#: Optional arrays of a plan (None when not kept): the primal-dual point of its NLP.
POINT_ARRAYS = ("point_w", "point_lam_x", "point_lam_g")


@dataclass(frozen=True, eq=False)
class Plan:
    """A solved plan. `meta` holds what it was computed for (course hash, rider, settings).

    Attributes:
        power_w: power at the contact point, negative when braking (model.md section 2).
        ax_mps2: tyre longitudinal force per unit mass (model.md C16).
        ay_mps2: lateral (centripetal) acceleration `v^2 tan(delta) / L`.
        friction_use: the friction-ellipse left-hand side of C16 (<= 1 when feasible).
        costate_v_s_per_mps: what one more m/s at a node is worth in objective (~finish
            time) from there on, along the optimum (negative: speed saves time); the
            IPOPT multiplier of that node's speed continuity constraint (the adjoint).
            The receding horizon prices the speed it carries past its end with it.
        solver_status: IPOPT's raw return status (`Invalid_Plan` when the solver converged
            but the plan failed its verification).
        status: what the outcome means (`solver.PlanStatus` value: converged, capped,
            failed, invalid); only a `converged` plan is verified and fit for use.
            `meta["verification"]` holds the replay's figures (`verify.Verification`).
        point_w, point_lam_x, point_lam_g: the primal-dual point of the NLP this plan
            solves, on its nodes `s_m`: the decision vector (the NLP's layout), its bound
            and its constraint multipliers; all None when not kept (or a file without
            them). Why a plan keeps them: a re-solve of the rest of the course from the
            plan resumes from them (`course_nlp.PrimalDual`); from the primal point
            alone the first re-solve of the Zwift Bologna ride took 116 IPOPT
            iterations, warm ones 6-43 (bench/RESULTS.md, 2026-12-02).
    """

    model: str
    s_m: np.ndarray
    t_s: np.ndarray
    n_m: np.ndarray
    alpha_rad: np.ndarray
    phi_rad: np.ndarray
    phi_dot_radps: np.ndarray
    v_mps: np.ndarray
    w_n: np.ndarray
    delta_n: np.ndarray
    e_n: np.ndarray
    u_delta: np.ndarray
    u_w: np.ndarray
    power_w: np.ndarray
    w_prime_j: np.ndarray
    ax_mps2: np.ndarray
    ay_mps2: np.ndarray
    friction_use: np.ndarray
    costate_v_s_per_mps: np.ndarray
    solver_status: str
    iterations: int
    solve_time_s: float
    meta: dict[str, Any] = field(default_factory=dict)
    status: str = "converged"
    point_w: np.ndarray | None = None
    point_lam_x: np.ndarray | None = None
    point_lam_g: np.ndarray | None = None

    @property
    def converged(self) -> bool:
        """Converged and verified: the only plan fit for use."""
        return self.status == "converged"

    @property
    def finish_time_s(self) -> float:
        return float(self.t_s[-1])

    @property
    def has_point(self) -> bool:
        """Whether the plan keeps the primal-dual point of its NLP (`POINT_ARRAYS`)."""
        return all(getattr(self, k) is not None for k in POINT_ARRAYS)

    @property
    def n_nodes(self) -> int:
        return len(self.s_m)

    @property
    def pedal_power_w(self) -> np.ndarray:
        """What the rider pedals at each node: `power_w` with braking as 0 W (a rider's
        power meter never reads the brakes)."""
        pedal: np.ndarray = np.clip(self.power_w, 0.0, None)
        return pedal

    def at(self, name: str, s_m: float | np.ndarray) -> np.ndarray:
        """Linear interpolation of one plan array (by attribute name) at `s_m`."""
        values: np.ndarray = np.interp(s_m, self.s_m, getattr(self, name))
        return values

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        header = {"format": _FORMAT, "model": self.model, "solver_status": self.solver_status,
                  "status": self.status, "iterations": self.iterations,
                  "solve_time_s": self.solve_time_s, "meta": self.meta}
        kept = POINT_ARRAYS if self.has_point else ()
        arrays = {k: getattr(self, k) for k in (*PLAN_ARRAYS, *kept)}
        with path.open("wb") as fh:
            np.savez_compressed(fh, header=np.array(json.dumps(header)), **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Plan:
        """Read a plan written by `save` (its `POINT_ARRAYS` if the file has them).

        Raises:
            IttError: not a plan file.
        """
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                header = json.loads(str(data["header"]))
                arrays: dict[str, Any] = {k: np.array(data[k]) for k in PLAN_ARRAYS}
                if all(k in data.files for k in POINT_ARRAYS):
                    arrays |= {k: np.array(data[k]) for k in POINT_ARRAYS}
        except (OSError, ValueError, KeyError) as err:
            raise IttError(f"{path}: not an itt-planner plan file ({err})") from None
        if header.get("format") != _FORMAT:
            raise IttError(f"{path}: not an itt-planner plan file")
        names = {f.name for f in fields(cls)}
        if "status" not in header:  # a file from before the status: unverified, IPOPT's
            from itt_planner.ocp.solver import PlanStatus  # noqa: PLC0415

            header["status"] = PlanStatus.of(str(header.get("solver_status", ""))).value
        return cls(**arrays, **{k: v for k, v in header.items() if k in names})


@dataclass(frozen=True)
class CornerRow:
    """How a plan rides one corner (SI units).

    Attributes:
        braking_s_m: where braking (W_n < 0) starts before the apex, or None if the
            rider does not brake for this corner.
        max_lean_rad: largest |phi| between entry and exit.
        time_s: time from the corner's entry to its exit.
    """

    apex_s_m: float
    min_radius_m: float
    braking_s_m: float | None
    entry_speed_mps: float
    apex_speed_mps: float
    exit_speed_mps: float
    max_lean_rad: float
    time_s: float


def corner_table(plan: Plan, corners: tuple[Any, ...], lookback_m: float = 300.0
                 ) -> list[CornerRow]:
    """One row per course corner (`course.Corner`): braking point, speeds, lean, time.

    The braking point is the start of the last braking run within `lookback_m` before the
    apex and after the previous corner's apex (a corner taken without braking has none;
    it did not inherit the braking of the corner before it)."""
    rows = []
    prev_apex = -np.inf
    for c in corners:
        before = ((plan.s_m >= max(c.apex_s_m - lookback_m, prev_apex))
                  & (plan.s_m <= c.apex_s_m))
        prev_apex = c.apex_s_m
        braking = before & (plan.w_n < 0)
        braking_s = None
        if np.any(braking):
            # The start of the last braking run before the apex.
            idx = np.flatnonzero(braking)
            gaps = np.flatnonzero(np.diff(idx) > 1)
            braking_s = float(plan.s_m[idx[gaps[-1] + 1] if len(gaps) else idx[0]])
        inside = (plan.s_m >= c.entry_s_m) & (plan.s_m <= c.exit_s_m)
        lean = float(np.max(np.abs(plan.phi_rad[inside]))) if np.any(inside) else float(
            abs(plan.at("phi_rad", c.apex_s_m)))
        rows.append(CornerRow(
            apex_s_m=c.apex_s_m, min_radius_m=c.min_radius_m, braking_s_m=braking_s,
            entry_speed_mps=float(plan.at("v_mps", c.entry_s_m)),
            apex_speed_mps=float(plan.at("v_mps", c.apex_s_m)),
            exit_speed_mps=float(plan.at("v_mps", c.exit_s_m)), max_lean_rad=lean,
            time_s=float(plan.at("t_s", c.exit_s_m) - plan.at("t_s", c.entry_s_m))))
    return rows


def splits(plan: Plan, every_m: float = 1000.0) -> list[dict[str, float]]:
    """Split times every `every_m` (and at the finish): elapsed, split, mean speed/power.

    Mean power is time-weighted over the split (the plan's power per interval).
    """
    marks = np.append(np.arange(every_m, plan.s_m[-1], every_m), plan.s_m[-1])
    t_marks = plan.at("t_s", marks)
    out, s_prev, t_prev = [], float(plan.s_m[0]), 0.0
    dt = np.diff(plan.t_s)
    for s, t in zip(marks, t_marks, strict=True):
        sel = (plan.s_m[:-1] >= s_prev) & (plan.s_m[:-1] < s)
        energy = float(np.sum(plan.power_w[:-1][sel] * dt[sel]))
        split = float(t - t_prev)
        out.append({"s_m": float(s), "elapsed_s": float(t), "split_s": split,
                    "mean_speed_mps": (float(s) - s_prev) / split if split > 0 else 0.0,
                    "mean_power_w": energy / float(np.sum(dt[sel])) if np.any(sel) else 0.0})
        s_prev, t_prev = float(s), float(t)
    return out
