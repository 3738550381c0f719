"""What a receding-horizon replan is asked for (`HorizonSettings`: window, terminal
treatment, budgets) and what it returns (`HorizonSolution`: the profiles over the window,
its outcome and the predicted finish). Why each setting is what it is: `horizon`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the solver imports CasADi; settings stay light for the live engine
    from itt_planner.ocp.solver import PlanStatus

#: Status of a budget-capped iterate that passed `HorizonNlp.feasible` (success=True).
SUBOPTIMAL_FEASIBLE = "Suboptimal_Feasible"
#: Status of the rescue's smooth solution with exact W' that passed `feasible` (success=True,
#: `outcome` the polish's: never converged, so counted as unconverged; `horizon_rescue`).
SMOOTHED_FEASIBLE = "Smoothed_Feasible"
#: Status added when a solution fails `HorizonNlp.resolved` (an integration artefact:
#: success=False, the last good advice stays).
UNRESOLVED = "Unresolved_Dynamics"
#: Status added when a converged solution rides its path-constraint slacks beyond grip
#: (C16) or the pedalling gate (C15), more than the measured start already did
#: (`HorizonNlp.feasible`): the next attempt is tried, and if none is usable the last
#: good advice stays.
BEYOND_LIMITS = "Beyond_Limits"


@dataclass(frozen=True)
class HorizonSettings:
    """Size, terminal treatment and budgets of the receding-horizon OCP.

    Attributes:
        horizon_m: length of the window ahead of the rider.
        max_window_s, min_window_m: the window ends earlier where the plan takes more
            than `max_window_s` over `horizon_m` (a slow climb), but not closer than
            `min_window_m`; 0 s: always `horizon_m`. Why: the node count is fixed, so a
            1 km window up the 13-16 % ramps of the Bologna ride (plan at 3.6 m/s,
            ~280 s) had 13-17 m intervals of ~4 s each, where `dv/ds = a/v` is stiff:
            cold starts from the plan failed at the cap one after the other (a run of
            ~40 fallbacks), and one that converged rode an integration artefact
            (28 m/s up a 13 % grade); over 400 m, 37 of 42 of those replans converged,
            median 18 iterations (bench/RESULTS.md). 120 s leaves every window at
            >= 8.3 m/s (30 km/h) its full `horizon_m`.
        max_density_ratio: the window also ends where the mesh would ask for this many
            times `n_intervals` (its spacing, `mesh.target_spacing`: ~1 m in a hairpin),
            but not closer than `min_window_m`; 0: no such end. Why: the node count is
            fixed, so a 1 km window through six 15-20 m switchbacks (a Suunto watch's GPX,
            161-207 intervals asked) had intervals of 10-15 m through each hairpin, and a
            slow rider's replans ran to the iteration cap for 200 m at a time: 6.5 % of
            the advice were fallbacks, 4.1 % with this end (bench/RESULTS.md). A road
            course's 1 km asks at most 81 (St John's) to 138 (Tokyo's lap): 2x ends 0-5 %
            of their windows early; 1.5x would end 13-28 %.
        n_intervals: fixed number of shooting intervals over the window.
        substeps: RK4 substeps per interval ...
        stiff_substeps, stiff_ratio: ... and in a window where one step per interval
            is outside RK4's stable range (`HorizonPlanner.stiff`: `h 2 a / v^2` over
            `stiff_ratio` somewhere). Why: the 4-5 m intervals of a window up gpxpy's
            korita-zbevnica ramp (22 %, a spent rider at 2.2 m/s) were, and IPOPT rode
            the artefact (2.5 -> 27 m/s in 10 m, "converged"): advice of 0 W that
            stalled the virtual rider. Two substeps everywhere cost 26 % of the median
            replan on verona-like and lost 3 of 50 replans of test_horizon's technical
            descent (bench/RESULTS.md, 2026-12-04). 1.0 since 2026-12-05: a slow rider
            (3.5-5 m/s) up a switchback circuit's climbs had 18-38 m intervals at 1.1-2.0,
            and their solutions failed the check below (`Unresolved_Dynamics`): 47 of 73
            fallbacks; at 1.0, 8 fallbacks of 1,656 advice (10 % of St John's windows
            get two substeps instead of 3 %).
        resolve_tol_mps: a solution is usable only if every interval, integrated again
            with four times the substeps, ends within this (plus 5 % of the speed) of
            its next node's speed (`HorizonNlp.resolved`): the artefact check.
        h_min_m, h_max_m: finest and coarsest window intervals (before the fixed node
            count rescales them).
        near_grade: how fast the spacing may grow with the distance ahead of the
            rider (m per m), so the first intervals (the advice now) are fine.
        slack_weight: penalty per unit of path-constraint slack (s).
        v_weight: terminal speed penalty (s per (m/s)^2).
        max_iter, max_wall_time_s: budget of each attempt (warm, retry, the rescue's
            smooth solve) and of the whole replan (shared as `warm_share`,
            `rescue_share` say; a deterministic replay has no wall-time cap). 150 since
            2026-12-05: at 60, replans that needed 61-150 iterations (a rider far off
            the plan through switchbacks: median 77, re-solved uncapped) failed all
            three attempts: on a switchback circuit 166 of 1,656 advice were fallbacks,
            9 at 150 (bench/RESULTS.md, 2026-12-05).
        tol: IPOPT tolerance (a replan needs less accuracy than the plan). 1e-4 since
            the NLP is unscaled: with 1e-3 the closed loop on the technical test course
            finished 1.3 % behind the optimum (tests/sim/test_simulate.py), at the same
            iteration counts over the verona-like sweep.
        acceptable_iter: IPOPT stops after this many consecutive iterates within
            10 x `tol` ("Solved_To_Acceptable_Level", counted as success): the advice
            does not change measurably in the last digits, the latency ~2x.
        eps_wn, sharpness_w: smoothing widths of max(W_n, 0) and of the E9 switch at
            critical power (`model.dynamics`) in the horizon model.
        w_delta, w_power: objective weights w_1, w_2 (model.md section 5).
        warm_multipliers: also shift the previous multipliers (a primal-dual warm
            start). On the Zwift Bologna replay's 961 horizon solves (bench/RESULTS.md,
            2026-12-02): 13,934 -> 11,011 iterations, median 8 -> 6, the planned power
            10 m ahead within 0.3 W (p95); on the perturbed technical-descent sweep
            (tests/ocp/test_horizon.py) 50 of 50 usable instead of 49 (1,900 iterations
            instead of 1,592: a 50 m jump with new noise is no shifted replan). With it,
            a smaller initial barrier (1e-5) cut Bologna's iterations to 8,918 but left
            only 47 of 50 of that sweep usable: `solver._HORIZON_WARM` keeps 1e-4.
        margin_m: distance kept from each road edge (C11).
        feasible_tol: a budget-capped iterate is returned as success
            ("Suboptimal_Feasible") when its continuity gaps, bounds and path-constraint
            residuals are within this (state units: m, rad, m/s, E_n fractions).
        grip_tol: ... and its path-constraint slacks (grip C16, pedalling C15) within
            this beyond what the measured initial state already uses.
        warm_share: share of `max_wall_time_s` given to the warm attempt; the rest is
            the cold retry's (from the plan) when the warm attempt is not usable.
        reset_after_failures: after this many unusable replans in a row the last good
            solution is dropped and the next replan starts from the plan.
        corner_cap_use, corner_cap_tol_mps, corner_cap_brake_g: where the plan's friction
            use is at least `corner_cap_use`, the horizon's speed is capped at the plan's
            plus `corner_cap_tol_mps`, or what braking at `corner_cap_brake_g` g from the
            rider's speed reaches (`corner_speed_cap`).
        rescue_sharpness_w: E9 switch width (W) of the rescue's smooth NLP, tried when
            the exact attempts failed (`horizon` module docstring, `horizon_rescue`);
            not above `sharpness_w` (e.g. 0): no rescue.
        rescue_share: share of `max_wall_time_s` the rescue gets (the warm attempt and
            the cold retry share the rest as before), two thirds of it for the smooth
            solve, a third for the polish.
        polish_max_iter: iteration cap of the polish (the exact NLP from the smooth
            solution); the smooth solve has `max_iter`, like every attempt.
    """

    horizon_m: float = 1000.0
    max_window_s: float = 120.0
    min_window_m: float = 200.0
    max_density_ratio: float = 2.0
    n_intervals: int = 60
    substeps: int = 1
    stiff_substeps: int = 2
    stiff_ratio: float = 1.0
    resolve_tol_mps: float = 0.3
    h_min_m: float = 2.5
    h_max_m: float = 30.0
    near_grade: float = 0.1
    slack_weight: float = 100.0
    v_weight: float = 1.0
    max_iter: int = 150
    max_wall_time_s: float = 0.8
    tol: float = 1e-4
    acceptable_iter: int = 2
    margin_m: float = 0.5
    eps_wn: float = 1e-3
    sharpness_w: float = 5.0
    w_delta: float = 0.01
    w_power: float = 0.01
    warm_multipliers: bool = True
    feasible_tol: float = 1e-3
    grip_tol: float = 0.02
    warm_share: float = 0.6
    reset_after_failures: int = 3
    corner_cap_use: float = 0.9
    corner_cap_tol_mps: float = 0.5
    corner_cap_brake_g: float = 0.3
    rescue_sharpness_w: float = 20.0
    rescue_share: float = 0.3
    polish_max_iter: int = 30


@dataclass(frozen=True, eq=False)
class HorizonSolution:
    """One replan: profiles over the window (arc length `s_m` on the course, SI units).

    `t_s` starts at 0 at the rider's position. `phi_rad` is the steady lean of the
    horizon model. `predicted_finish_s` is the elapsed time from the ride start at the
    finish line: elapsed now + horizon time + the plan's time from the horizon end to
    the finish. `w_prime_finish_j` likewise adds the plan's W' change over the rest of
    the course.

    `success`: the profiles are valid advice. `outcome` (`solver.PlanStatus`): how the
    last solver attempt ended, `converged`, `capped` (with `success`: a capped iterate
    that passed the feasibility check, `status` "Suboptimal_Feasible") or `failed`; after
    a rescue (`horizon_rescue`) the polish's, and with `success` and `status`
    "Smoothed_Feasible" (the smooth solution with exact W') `failed` or `capped`: usable,
    never counted as converged.
    `status`: the raw solver statuses, the attempts' joined by "; " after a failure.
    """

    s_m: np.ndarray
    n_m: np.ndarray
    v_mps: np.ndarray
    power_w: np.ndarray
    phi_rad: np.ndarray
    t_s: np.ndarray
    w_prime_j: np.ndarray
    success: bool
    status: str
    outcome: PlanStatus
    iterations: int
    solve_time_s: float
    predicted_finish_s: float
    w_prime_finish_j: float

    @property
    def target_power_w(self) -> float:
        """Power to ride now: the first interval's end (the start holds the measured one)."""
        return float(self.power_w[1])
