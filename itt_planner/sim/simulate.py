"""Closed-loop virtual rider: the 3D model integrated in time, sensors, scenarios.

`simulate_ride` rides a course with a simulated rider whose truth (critical power, wind,
behaviour) may differ from what the planner believes. The rider follows advice (target
power with a lag and noise, the advised line with a path-following controller); the
sensors emit stamped `GpsFix` (1 Hz, 3 m noise), `WheelSpeed` and `PowerReading` samples;
the pacing engine turns them into advice. The dynamics are B's 3D model
(`model.build_3d`, E1-E9) converted from the spatial to the time domain
(`dx/dt = (dx/ds) / (dt/ds)`), so the simulator and the planner share one set of
equations.

This module also holds `hairpin_course`, a short synthetic technical course (a hairpin,
a road crossing itself, an S-bend) used by the closed-loop tests and the CLI's quick
runs.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass, field
from enum import Enum

import casadi as ca
import numpy as np
from tqdm import tqdm

from itt_planner.live.advice import Advice
from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.course.geometry import Course
from itt_planner.course.builder import build_course
from itt_planner.live.engine import EngineSettings, PacingEngine
from itt_planner.errors import IttError
from itt_planner.model.dynamics import build_3d
from itt_planner.model.params import PARAMS, ModelParams
from itt_planner.ocp.plan import Plan
from itt_planner.model.rider import Rider
from itt_planner.live.samples import GpsFix, PowerReading, Sample, WheelSpeed


# ---- a short technical test course ---------------------------------------------------------
#: Segments (course_builder format) of `hairpin_course`: a climb, a 270 deg bend whose
#: exit crosses the first straight, a 12 m hairpin on a descent, an S-bend.
HAIRPIN_COURSE = {
    "name": "hairpin-test",
    "description": "SYNTHETIC ~2.8 km technical test course of the closed-loop tests.",
    "origin": {"lat_deg": 45.43, "lon_deg": 10.99, "alt_m": 100.0},
    "segments": [
        {"type": "straight", "length_m": 500, "grade_pct": 2},
        {"type": "clothoid", "length_m": 15, "radius_m": 50, "direction": "left"},
        {"type": "arc", "angle_deg": 253, "radius_m": 50, "direction": "left"},
        {"type": "clothoid", "length_m": 15},
        {"type": "straight", "length_m": 400, "grade_pct": -1},
        {"type": "clothoid", "length_m": 12, "radius_m": 30, "direction": "right"},
        {"type": "arc", "angle_deg": 67, "radius_m": 30, "direction": "right"},
        {"type": "clothoid", "length_m": 12},
        {"type": "straight", "length_m": 300, "grade_pct": -3},
        {"type": "clothoid", "length_m": 10, "radius_m": 12, "direction": "left", "grade_pct": -3},
        {"type": "arc", "angle_deg": 130, "radius_m": 12, "direction": "left"},
        {"type": "clothoid", "length_m": 10},
        {"type": "straight", "length_m": 500, "grade_pct": 1},
        {"type": "clothoid", "length_m": 10, "radius_m": 40, "direction": "right"},
        {"type": "arc", "angle_deg": 30, "radius_m": 40, "direction": "right"},
        {"type": "clothoid", "length_m": 20, "radius_m": 40, "direction": "left"},
        {"type": "arc", "angle_deg": 30, "radius_m": 40, "direction": "left"},
        {"type": "clothoid", "length_m": 10},
        {"type": "straight", "length_m": 600},
    ],
}


def hairpin_course(ds_m: float = 1.0) -> Course:
    """The ~2.8 km synthetic technical course `HAIRPIN_COURSE` (course_builder)."""
    return build_course(HAIRPIN_COURSE, source="itt_planner.sim.simulate.HAIRPIN_COURSE", ds_m=ds_m)


# ---- sensors ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class SensorSettings:
    """Noise of the simulated sensors.

    GPS error is a slowly wandering bias (first-order Gauss-Markov, `gps_tau_s`) plus
    white noise: consecutive bike-GPS fixes are strongly correlated, which is what makes
    map matching hard. `gps_std_m` is the total horizontal 1-sigma per axis.

    Attributes:
        gps_period_s: fix interval (1 Hz).
        wheel_scale: the wheel sensor's circumference error (1.01 = reads 1 % fast).
        dropouts: (start, duration) intervals of ride time without GPS.
        outliers: ride times at which the fix jumps `outlier_m` sideways.
    """

    gps_period_s: float = 1.0
    gps_std_m: float = 3.0
    gps_tau_s: float = 20.0
    gps_white_fraction: float = 0.3
    speed_period_s: float = 1.0
    speed_std_mps: float = 0.15
    wheel_scale: float = 1.01
    power_period_s: float = 1.0
    power_std_w: float = 8.0
    dropouts: tuple[tuple[float, float], ...] = ()
    outliers: tuple[float, ...] = ()
    outlier_m: float = 100.0


class Sensors:
    """GPS, wheel-speed and power sensors sampling a true trajectory at their own rates.

    Args:
        course: for ENU <-> lat/lon.
        settings: noise levels, dropouts and outliers.
        rng: the random stream (seeded by the caller for reproducible rides).
        t0_s: stamp of ride time 0 (POSIX seconds for a realistic log).
    """

    def __init__(self, course: Course, settings: SensorSettings, rng: np.random.Generator,
                 t0_s: float = 0.0) -> None:
        self.course, self.settings, self.rng, self.t0_s = course, settings, rng, t0_s
        st = settings
        self._white = st.gps_std_m * math.sqrt(st.gps_white_fraction)
        self._bias_std = st.gps_std_m * math.sqrt(1 - st.gps_white_fraction)
        self._bias = rng.normal(0.0, self._bias_std, 2)
        self._next = {"gps": 0.0, "speed": 0.0, "power": 0.0}

    def sample(self, t: float, s_m: float, n_m: float, v_mps: float, power_w: float
               ) -> list[Sample]:
        """The samples due at ride time `t` (each sensor fires once its period is up)."""
        st, out = self.settings, []
        eps = 1e-9
        if t + eps >= self._next["gps"]:
            self._next["gps"] += st.gps_period_s
            fix = self._gps(t, s_m, n_m)
            if fix is not None:
                out.append(fix)
        if t + eps >= self._next["speed"]:
            self._next["speed"] += st.speed_period_s
            v = v_mps * st.wheel_scale + self.rng.normal(0.0, st.speed_std_mps)
            out.append(WheelSpeed(self.t0_s + t, max(v, 0.0)))
        if t + eps >= self._next["power"]:
            self._next["power"] += st.power_period_s
            # A power meter measures pedalling only: braking reads as zero.
            p = max(power_w + self.rng.normal(0.0, st.power_std_w), 0.0) if power_w > 0 else 0.0
            out.append(PowerReading(self.t0_s + t, p))
        return out

    def _gps(self, t: float, s_m: float, n_m: float) -> GpsFix | None:
        st = self.settings
        a = math.exp(-st.gps_period_s / st.gps_tau_s)
        self._bias = a * self._bias + math.sqrt(1 - a * a) * self.rng.normal(
            0.0, self._bias_std, 2)
        if any(d0 <= t < d0 + dur for d0, dur in st.dropouts):
            return None
        x, y, z = (float(c) for c in self.course.enu_at(s_m, n_m))
        ex, ey = self._bias + self.rng.normal(0.0, self._white, 2)
        if any(abs(t - o) < 1e-6 for o in st.outliers):
            th = float(self.course.at("theta_rad", s_m))
            ex, ey = ex - st.outlier_m * math.sin(th), ey + st.outlier_m * math.cos(th)
        lat, lon, alt = self.course.to_geodetic(x + ex, y + ey, z)
        return GpsFix(self.t0_s + t, float(lat), float(lon), float(alt), st.gps_std_m)


def sensor_samples(course: Course, t_s: np.ndarray, s_m: np.ndarray, n_m: np.ndarray,
                   v_mps: np.ndarray, power_w: np.ndarray, rng: np.random.Generator,
                   settings: SensorSettings = SensorSettings(), t0_s: float = 0.0
                   ) -> list[Sample]:
    """All samples of a recorded true trajectory (arrays over `t_s`), in stamp order."""
    sensors = Sensors(course, settings, rng, t0_s)
    out: list[Sample] = []
    for k in range(len(t_s)):
        out += sensors.sample(float(t_s[k]), float(s_m[k]), float(n_m[k]), float(v_mps[k]),
                              float(power_w[k]))
    return out


# ---- scenarios --------------------------------------------------------------------------------
class Scenario(str, Enum):
    """How the truth differs from the planner's belief (issue 4, item 5)."""

    NOMINAL = "nominal"
    CP_OVERESTIMATED = "cp-overestimated"
    HEADWIND = "headwind"
    HOT_START = "hot-start"


class Policy(str, Enum):
    """What the simulated rider follows."""

    REPLANNED = "replanned"  # the pacing engine's advice, replanned in the loop
    OPEN_LOOP = "open_loop"  # the full-course plan, blindly
    EVEN_CP = "even_cp"  # constant critical power (the plan's line and corner speeds)


@dataclass(frozen=True)
class ScenarioSettings:
    """Magnitudes of the scenarios.

    Attributes:
        cp_factor: true CP / believed CP in `cp-overestimated`.
        headwind_mps: unforecast head wind over the second half in `headwind`.
        hot_start_m: how far the rider ignores advice in `hot-start` (clipped to a third
            of the course so short test courses keep a part to recover on) ...
        hot_start_factor: ... riding this factor times the plan's power.
    """

    cp_factor: float = 0.95
    headwind_mps: float = 3.0
    hot_start_m: float = 2000.0
    hot_start_factor: float = 1.15


@dataclass(frozen=True)
class RiderBehaviour:
    """The simulated rider's imperfections: lag and noise in following a power target,
    and the gains of the path-following controller (steering by lean, section notes in
    `_closed_loop_step`).

    Attributes:
        power_lag_s: first-order lag of the delivered power behind the target.
        power_noise: relative 1-sigma of the rider's power wander ...
        power_noise_tau_s: ... and its correlation time.
        brake_margin_mps: the rider brakes when faster than the advised speed by this.
        brake_lookahead_s: ... looking this far ahead along the advised profile.
        w_reserve: below this fraction of W' the rider cannot exceed CP (exhausted).
        roll_omega_radps: bandwidth of the lean loop (a gentler lean needs less
            counter-steer, which the tyres must carry too).
        grip_lateral: fraction of `mu_y g` the rider uses in a steady turn (the rest is
            headroom for the lean loop); sets the corner speed the rider brakes for.
        grip_brake: fraction of `mu_x g` the rider plans to brake at when looking ahead.
        brake_gain: braking command `-W_n` per m/s over the brake speed.
    """

    power_lag_s: float = 0.8
    power_noise: float = 0.03
    power_noise_tau_s: float = 5.0
    brake_margin_mps: float = 1.0
    brake_lookahead_s: float = 0.5
    w_reserve: float = 0.005
    k_lateral_ps: float = 0.3
    k_heading_ps: float = 1.0
    roll_omega_radps: float = 3.0
    steer_preview_s: float = 0.8
    grip_lateral: float = 0.92
    grip_brake: float = 0.5
    brake_gain: float = 0.5


def planning_conditions(conditions: Conditions = Conditions(),
                        behaviour: RiderBehaviour = RiderBehaviour()) -> Conditions:
    """What the planner believes when the truth is `conditions` and the rider `behaviour`.

    The road and the air as they are, with the lateral grip the rider really uses in a
    steady turn (`behaviour.grip_lateral` of `mu_y`). Why: a plan cornering at 100 % of
    `mu_y` is one this rider cannot follow (it keeps the rest as headroom for leaning
    in and out), so it is not the optimum for this rider; with these conditions the
    belief equals the truth in `nominal`, and the plan's finish time is the optimum
    for the grip the rider uses. Solve the full-course plan with them
    (`simulate_ride`'s engine plans its horizon with them too).
    """
    return conditions.with_lateral_grip(behaviour.grip_lateral)


# ---- the closed-loop dynamics -----------------------------------------------------------------
#: State and reference layout of `_closed_loop_step`.
_REFS = ("n_ref", "dn_ref_ds", "w_cmd", "v_brake", "kappa_preview")


def _closed_loop_step(behaviour: RiderBehaviour, substeps: int) -> ca.Function:
    """One time step of the 3D model (E1-E9 via `model.build_3d`) under the rider's
    controller: `(x, s, road, p, ref, dt) -> (x_next, s_next)`.

    Time domain: `dx/dt = (dx/ds) / (dt/ds)` and `ds/dt = 1 / (dt/ds)` (E8).
    Lateral control, a cascade any rider does without thinking: the reference line's
    curvature a moment ahead (feed-forward) and the heading error to the line set a
    desired yaw rate; the steady lean of that turn,
    `tan(phi) = -v r / g` (E5), is the desired lean; steering is chosen so the roll
    dynamics E5 follow it with a critically damped response (feedback linearisation of
    E5 for the yaw rate, then `delta = atan(r L / v)`). Steering is imposed directly
    (its rate is unbounded in the model, C14 bounds its angle). Grip (C16) is a hard
    limit of the truth: the desired turn is capped at `grip_lateral mu_y g`, the
    steering at `|a_y| <= mu_y g`, and the longitudinal tyre force (pedalling or
    braking) gets only what the ellipse leaves, so the friction use never exceeds 1; a
    rider who is too fast runs wide. Power: the target (normalised `W_n`) with a
    first-order lag, braking when faster than the advised speed or than the grip
    envelope ahead (`_Reference.at`), no pedalling at high lean (C15), and at most CP
    when W' is exhausted.
    """
    b = behaviour
    model = build_3d()
    x = ca.SX.sym("x", model.nx)
    s = ca.SX.sym("s")
    road = ca.SX.sym("road", 4)
    p = ca.SX.sym("p", len(PARAMS))
    ref = ca.SX.sym("ref", len(_REFS))
    dt = ca.SX.sym("dt")
    q = {name: p[i] for i, name in enumerate(PARAMS)}
    g = GRAVITY_MPS2
    n_ref, dn_ref_ds, w_target, v_brake, kappa_ff = (ref[i] for i in range(len(_REFS)))
    i_delta, i_w = model.index("delta_n"), model.index("w_n")

    def controlled(xk: ca.SX) -> tuple[ca.SX, ca.SX]:
        n, alpha, phi, phi_dot, v, w_n, _, e_n = (xk[i] for i in range(model.nx))
        kappa = road[0]
        one_nk = 1 - n * kappa
        alpha_ref = ca.atan(dn_ref_ds * one_nk)
        # The lateral loop must stay well slower than the heading loop: its gain in
        # 1/s is `k_lateral_ps` whatever the speed (dn/dt = v alpha).
        err_n = ca.fmin(ca.fmax(b.k_lateral_ps * (n - n_ref) / ca.fmax(v, 3.0), -0.3), 0.3)
        # Feed-forward on the curvature of the LINE followed, a moment ahead (leaning in
        # takes time): a line that cuts a hairpin turns unlike the road; steering by the
        # road's curvature left the rider 2-5 m off the line there (bench/RESULTS.md).
        yaw_des = kappa_ff * v + b.k_heading_ps * (alpha_ref - err_n - alpha)
        # Grip (C16): the rider never asks for a turn tighter than the tyres carry, and
        # keeps headroom below it for the roll loop's steering transients.
        v_safe = ca.fmax(v, 0.5)
        ay_max = q["mu_y"] * g
        yaw_lim = b.grip_lateral * ay_max / v_safe
        yaw_des = ca.fmin(ca.fmax(yaw_des, -yaw_lim), yaw_lim)
        phi_des = -ca.atan(v * yaw_des / g)
        omega = b.roll_omega_radps
        phi_ddot_des = -omega ** 2 * (phi - phi_des) - 2 * omega * phi_dot
        i_x0 = q["roll_inertia"] + q["com_height"] ** 2 * q["mass"]
        c = q["com_height"] * q["mass"] / i_x0
        yaw_cmd = (phi_ddot_des / c - g * ca.sin(phi)) / (v_safe * ca.cos(phi))
        # Tyre limit on the steering itself: |a_y| = v^2 tan(delta) / L <= mu_y g. A
        # rider who would need more runs wide (n grows), as on a real road.
        tan_max = ay_max * q["wheelbase"] / (v_safe * v_safe)
        tan_delta = ca.fmin(ca.fmax(yaw_cmd * q["wheelbase"] / v_safe, -tan_max), tan_max)
        delta = ca.fmin(ca.fmax(ca.atan(tan_delta), -q["steer_max"]), q["steer_max"])
        # An exhausted rider cannot hold more than CP: the cap acts on the delivered
        # power at once (not through the lag), so W' cannot be overdrawn.
        cap = (q["cp"] - 10.0) / q["p_max"]  # below CP (the E9 switch is smoothed ~5 W)
        w_applied = ca.if_else(e_n < b.w_reserve, ca.fmin(w_n, cap), w_n)
        # Braking is a hand on the lever, not the legs: it acts at once (no power lag),
        # so the rider slows to the envelope without overshooting it.
        over = v - v_brake - b.brake_margin_mps
        w_applied = ca.if_else(over > 0, ca.fmin(w_applied, ca.fmax(-b.brake_gain * over, -1)),
                               w_applied)
        # Friction ellipse C16 with the lateral force first (the line is held): the
        # tyre force along the road, pedalling or braking, gets what grip is left.
        ay_use = v * v * ca.tan(delta) / q["wheelbase"] / ay_max
        ax_room = ca.sqrt(ca.fmax(1 - ay_use * ay_use, 0))
        pedal_max = ax_room * q["mu_x"] * g * q["mass"] * ca.fmax(v, 0) / q["p_max"]
        w_applied = ca.fmin(ca.fmax(w_applied, -ax_room), pedal_max)
        x_ctrl = ca.vertcat(xk[:i_w], w_applied, xk[i_w + 1:i_delta], delta / q["steer_max"],
                            xk[i_delta + 1:])
        # Pedalling command (braking is applied above): the legs stop while braking.
        w_cmd = ca.if_else(over > 0, ca.fmin(w_target, 0), w_target)
        w_cmd = ca.fmax(w_cmd, -1)
        gate = ca.fmax(0, 1 - (phi / q["pedal_lean"]) ** 2)  # C15
        w_cmd = ca.fmin(w_cmd, gate)
        w_cmd = ca.if_else(e_n < b.w_reserve, ca.fmin(w_cmd, cap), w_cmd)
        u_w = (w_cmd - w_n) / b.power_lag_s * q["p_max"] / q["power_rate_max"]
        return x_ctrl, ca.vertcat(0, u_w)

    def deriv(xk: ca.SX) -> tuple[ca.SX, ca.SX]:
        x_ctrl, u = controlled(xk)
        dxds, dtds, _ = model.ode(x_ctrl, u, road, p)
        xdot = dxds / dtds
        xdot[i_delta] = 0  # steering is imposed, not integrated
        return xdot, 1 / dtds

    h = dt / substeps
    xk, sk = x, s
    for _ in range(substeps):
        k1, s1 = deriv(xk)
        k2, s2 = deriv(xk + h / 2 * k1)
        k3, s3 = deriv(xk + h / 2 * k2)
        k4, s4 = deriv(xk + h * k3)
        xk = xk + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        sk = sk + h / 6 * (s1 + 2 * s2 + 2 * s3 + s4)
    x_final, _ = controlled(xk)  # report the steering actually applied
    outputs = model.outputs(x_final, p)
    return ca.Function("closed_loop_step", [x, s, road, p, ref, dt],
                       [x_final, sk, outputs], ["x", "s", "road", "p", "ref", "dt"],
                       ["x_next", "s_next", "y"])


# ---- the ride ---------------------------------------------------------------------------------
@dataclass(eq=False)
class SimResult:
    """One simulated ride: truth arrays over time, sensor samples, advice.

    Attributes:
        t_s, s_m, n_m, v_mps, power_w, w_prime_j, friction_use: the truth every step
            (`power_w` at the contact point, negative when braking; W' with the TRUE CP).
        samples: every sensor sample, in stamp order (what a bag of the ride holds).
        advice: every advice of the engine (replanned rides only).
        finish_time_s: time at the finish line (NaN when `max_time_s` ran out first).
        solve_times_s: wall-clock replan latencies of the engine.
        cp_in_use_w: the engine's CP at the finish (lower than the believed one after
            it refitted CP from a rider who could not hold the advice; NaN without engine).
    """

    scenario: Scenario
    policy: Policy
    t_s: np.ndarray
    s_m: np.ndarray
    n_m: np.ndarray
    v_mps: np.ndarray
    power_w: np.ndarray
    w_prime_j: np.ndarray
    friction_use: np.ndarray
    samples: list[Sample] = field(default_factory=list)
    advice: list[Advice] = field(default_factory=list)
    finish_time_s: float = math.nan
    solve_times_s: list[float] = field(default_factory=list)
    fallbacks: int = 0
    cp_in_use_w: float = math.nan

    def summary(self) -> dict[str, float]:
        """finish_time_s, w_prime_min_j, w_prime_end_j (and fallbacks, the engine's CP),
        JSON-ready."""
        return {"finish_time_s": round(float(self.finish_time_s), 3),
                "w_prime_min_j": round(float(self.w_prime_j.min()), 1),
                "w_prime_end_j": round(float(self.w_prime_j[-1]), 1),
                "max_friction_use": round(float(self.friction_use.max()), 3),
                "fallbacks": self.fallbacks,
                **({} if math.isnan(self.cp_in_use_w) else
                   {"cp_in_use_w": round(float(self.cp_in_use_w), 1)})}


#: Length over which `_Reference` averages the curvature of the line it follows.
_LINE_SMOOTH_M = 8.0
#: Length over which it takes the line's slope to the road.
_SLOPE_M = 2.0
#: How much of the line it followed the rider keeps behind the start of new advice.
_LEAD_IN_M = 30.0
#: Spacing of the road-aligned grid the rider's reference is sampled on.
_GRID_M = 0.5
#: The rider never brakes for a speed below this (a walking pace).
_V_BRAKE_MIN_MPS = 1.0


def _windowed_slope(s_m: np.ndarray, y: np.ndarray, window_m: float) -> np.ndarray:
    """dy/ds at every `s_m` as the change of `y` across `window_m` centred there (cut at
    the ends), `y` linear between the points."""
    lo = np.maximum(s_m - window_m / 2, s_m[0])
    hi = np.minimum(s_m + window_m / 2, s_m[-1])
    return (np.interp(hi, s_m, y) - np.interp(lo, s_m, y)) / np.maximum(hi - lo, 1e-9)


class _Reference:
    """What the rider follows: a profile over `s` (advice horizon or the whole plan), and
    the speed the rider can carry along its line within grip.

    Args:
        course: the road (the line's curvature is that of the ENU points at `(s, n)`).
        grip_lateral: fraction of `mu_y g` the rider plans to use in a steady turn.
        mu_y: lateral grip coefficient (C16).
    """

    def __init__(self, course: Course, s_m: np.ndarray, power_w: np.ndarray,
                 v_mps: np.ndarray, n_m: np.ndarray, grip_lateral: float, mu_y: float) -> None:
        grid = np.arange(math.ceil(s_m[0] / _GRID_M) * _GRID_M, s_m[-1], _GRID_M)
        if len(grid) > 2:
            # The line as a curve, sampled on a grid fixed to the road: its slope and
            # curvature are then the same whatever points a profile came as (advice
            # starts at an interpolated point; differences over the profile's own points
            # made the rider brake 2 kW where the same plan followed blindly did not).
            power_w, v_mps, n_m = (np.interp(grid, s_m, a) for a in (power_w, v_mps, n_m))
            s_m = grid
        self.s_m, self.power_w, self.v_mps, self.n_m = s_m, power_w, v_mps, n_m
        self.dn_ds = (_windowed_slope(s_m, n_m, _SLOPE_M) if len(s_m) > 2 else
                      np.gradient(n_m, s_m) if len(s_m) > 1 else np.zeros(1))
        self.v_grip = np.full(len(s_m), np.inf)
        self.kappa = np.zeros(len(s_m))
        if len(s_m) > 2:
            # Heading of the line = road heading + the line's angle to the road; its
            # change per metre travelled along the line is the line's curvature.
            one_nk = 1 - n_m * course.at("kappa_per_m", s_m)
            psi = np.unwrap(course.at("theta_rad", s_m) + np.arctan2(self.dn_ds, one_nk))
            dl_ds = np.hypot(one_nk, self.dn_ds)
            length = np.concatenate([[0.0], np.cumsum(0.5 * (dl_ds[1:] + dl_ds[:-1])
                                                      * np.diff(s_m))])
            # A rider feels the turn, not metre-scale wiggles of the sampled line: the
            # mean curvature over `_LINE_SMOOTH_M` of road, the heading change across it
            # per metre of line.
            self.kappa = (_windowed_slope(s_m, psi, _LINE_SMOOTH_M)
                          / np.maximum(_windowed_slope(s_m, length, _LINE_SMOOTH_M), 1e-6))
            # v^2 kappa <= grip_lateral mu_y g (C16 with a_x = 0).
            self.v_grip = np.sqrt(grip_lateral * mu_y * GRAVITY_MPS2
                                  / np.maximum(np.abs(self.kappa), 1e-9))

    @classmethod
    def of_plan(cls, course: Course, plan: Plan, grip_lateral: float, mu_y: float
                ) -> _Reference:
        return cls(course, plan.s_m, plan.power_w, plan.v_mps, plan.n_m, grip_lateral, mu_y)

    @classmethod
    def of_advice(cls, course: Course, advice: Advice, older: _Reference, grip_lateral: float,
                  mu_y: float) -> _Reference:
        """The advice's profile, led in by the `older` reference's last `_LEAD_IN_M`
        before the advice starts (its line shifted to meet the new one).

        Why: advice starts at the ESTIMATED position, which GPS noise puts a few metres
        ahead of the rider as often as behind, and the line's slope and curvature at a
        profile's first points are one-sided differences. A line cut in a hairpin then
        read as a sharper turn for its first metres: the rider braked 1-2 kW there
        where the same plan followed blindly did not (bench/RESULTS.md). A rider does not
        lose the line it was following when new advice comes.
        """
        s0 = float(advice.horizon_s_m[0])
        lead = (older.s_m < s0) & (older.s_m >= s0 - _LEAD_IN_M)
        shift = float(advice.horizon_n_m[0] - np.interp(s0, older.s_m, older.n_m))
        return cls(course, np.concatenate([older.s_m[lead], advice.horizon_s_m]),
                   np.concatenate([older.power_w[lead], advice.horizon_power_w]),
                   np.concatenate([older.v_mps[lead], advice.horizon_speed_mps]),
                   np.concatenate([older.n_m[lead] + shift, advice.horizon_n_m]),
                   grip_lateral, mu_y)

    def at(self, s: float, v: float, behaviour: RiderBehaviour, decel_mps2: float
           ) -> tuple[float, float, float, float, float]:
        """Power one lag ahead, the brake speed, n and dn/ds at `s`, and the line's
        curvature `steer_preview_s` ahead (the turn the rider steers into).

        The brake speed is the lower of the advised speed's minimum a moment ahead and
        the grip envelope: the speed from which the rider can still slow, at
        `decel_mps2`, to what grip allows on the line ahead (less the brake margin,
        which the controller adds back: no tolerance on grip). No reaction distance:
        the controller's brake acts at once.
        """
        b = behaviour
        ahead = np.linspace(s, s + b.brake_lookahead_s * v, 5)
        v_ref = float(np.interp(ahead, self.s_m, self.v_mps).min())
        far = s + np.linspace(0.0, v * v / (2 * decel_mps2) + 1.0, 41)
        run = far - s
        grip = np.interp(far, self.s_m, self.v_grip, right=np.inf)
        v_env = float(np.sqrt(grip ** 2 + 2 * decel_mps2 * run).min())
        return (float(np.interp(s + b.power_lag_s * v, self.s_m, self.power_w)),
                max(min(v_ref, v_env - b.brake_margin_mps), _V_BRAKE_MIN_MPS),
                float(np.interp(s, self.s_m, self.n_m)), float(np.interp(s, self.s_m, self.dn_ds)),
                float(np.interp(s + b.steer_preview_s * v, self.s_m, self.kappa)))


def simulate_ride(course: Course, rider: Rider, plan: Plan, *,
                  scenario: Scenario | str = Scenario.NOMINAL, seed: int = 0,
                  policy: Policy | str = Policy.REPLANNED,
                  conditions: Conditions = Conditions(),
                  engine_settings: EngineSettings = EngineSettings(),
                  planner: object | None = None,
                  sensors: SensorSettings = SensorSettings(),
                  scenario_settings: ScenarioSettings = ScenarioSettings(),
                  behaviour: RiderBehaviour = RiderBehaviour(),
                  dt_s: float = 0.1, max_time_s: float | None = None,
                  t0_s: float = 0.0, progress: bool = False) -> SimResult:
    """Ride `course` in closed loop on the truth `conditions`.

    The planner believes `rider` and `planning_conditions(conditions, behaviour)`: the
    same road and air, with the lateral grip the rider uses; `plan` should be solved
    for those (then, in `nominal`, belief equals truth). The truth differs by
    `scenario`. With `policy=replanned` the sensor samples feed a
    `PacingEngine` (built on `planner`, a shared `HorizonPlanner` that keeps its own
    conditions - build it with `planning_conditions` - or its own), whose
    advice the rider follows from the moment it is published (the engine runs in its
    deterministic mode: simulated time is not the wall clock); the other policies follow
    the full-course `plan` or constant CP and need no engine. The rider's noise and the
    sensors draw from `seed`, identically for every policy, so policies compare on the
    same truth. `progress` draws a bar over the distance on stderr.

    Raises:
        IttError: unknown scenario or policy name.
    """
    try:
        scenario, policy = Scenario(scenario), Policy(policy)
    except ValueError as err:
        raise IttError(f"simulate: {err}") from None
    sc = scenario_settings
    truth_rider = rider
    if scenario is Scenario.CP_OVERESTIMATED:
        truth_rider = dataclasses.replace(rider, critical_power_w=rider.critical_power_w
                                          * sc.cp_factor)
    par = ModelParams(truth_rider, conditions).vector()
    i_wind = PARAMS.index("wind_e")
    hot_start_m = min(sc.hot_start_m, course.length_m / 3)
    step = _step_function(behaviour)
    rng_rider = np.random.default_rng([seed, 1])
    sens = Sensors(course, sensors, np.random.default_rng([seed, 2]), t0_s)
    engine = None
    if policy is Policy.REPLANNED:
        # Simulated time is not the wall clock: the engine's deterministic mode judges
        # nothing by wall time (overruns, when a re-solve of the course is ready).
        engine = PacingEngine(course, rider, plan,
                              conditions=planning_conditions(conditions, behaviour),
                              settings=dataclasses.replace(engine_settings, deterministic=True),
                              planner=planner)  # type: ignore[arg-type]
    grip = (behaviour.grip_lateral, conditions.mu_y)
    decel = behaviour.grip_brake * conditions.mu_x * GRAVITY_MPS2
    plan_ref = _Reference.of_plan(course, plan, *grip)
    ref = plan_ref
    advice: list[Advice] = []
    samples: list[Sample] = []
    # Start as the plan does (model.md section 5): upright on the centre line, W_n = CP.
    x = np.zeros(8)
    x[4] = float(plan.v_mps[0])
    x[5] = rider.critical_power_w / rider.max_power_w
    x[7] = 1.0
    s, t = 0.0, 0.0
    noise = 0.0
    a_noise = math.exp(-dt_s / behaviour.power_noise_tau_s)
    limit = max_time_s if max_time_s is not None else 3.0 * plan.finish_time_s + 600.0
    rows = []
    finish = math.nan
    y = np.zeros(4)
    bar = tqdm(total=round(course.length_m), unit="m", desc=f"{scenario.value} {policy.value}",
               disable=not progress, file=sys.stderr, leave=False)
    while t < limit:
        bar.update(round(s) - bar.n)
        p_now = max(float(y[0]), 0.0)
        for smp in sens.sample(t, s, float(x[0]), float(x[4]), p_now):
            samples.append(smp)
            if engine is not None:
                engine.on_sample(smp)
        if engine is not None:
            adv = engine.update(t0_s + t)
            if adv is not None:
                advice.append(adv)
                ref = _Reference.of_advice(course, adv, ref, *grip)
        rows.append((t, s, x[0], x[4], y[0], x[7] * truth_rider.w_prime_j, y[3]))
        # The rider's target at the current point.
        follow = plan_ref if (ref is plan_ref or s >= ref.s_m[-1]) else ref
        if scenario is Scenario.HOT_START and s < hot_start_m:
            follow = plan_ref
        # The rider reads the target one lag ahead, so the delivered power is on time.
        power, v_brake, n_ref, dn_ds, kappa_ff = follow.at(s, float(x[4]), behaviour, decel)
        # The rider brakes for speeds (the advised speed ahead, the grip envelope), by
        # hand and at once in the controller; a negative advised power only means "stop
        # pedalling" (braking it blindly, through the leg's lag, double-brakes a rider
        # who is already slower than the advice).
        power = max(power, 0.0)
        if policy is Policy.EVEN_CP:
            power = rider.critical_power_w
        if scenario is Scenario.HOT_START and s < hot_start_m:
            power *= sc.hot_start_factor
        noise = a_noise * noise + math.sqrt(1 - a_noise ** 2) * rng_rider.normal(
            0.0, behaviour.power_noise)
        w_cmd = (power * (1 + noise) / rider.max_power_w if power >= 0 else
                 power / (conditions.mu_x * GRAVITY_MPS2 * rider.mass_kg * max(x[4], 1.0)))
        road = _road(course, s)
        if scenario is Scenario.HEADWIND and s >= course.length_m / 2:
            # A head wind follows the road: blowing against the centre-line heading.
            par = par.copy()
            par[i_wind] = -sc.headwind_mps * math.cos(road[2])
            par[i_wind + 1] = -sc.headwind_mps * math.sin(road[2])
        x_next, s_next, y_next = step(x, s, road, par, [n_ref, dn_ds, w_cmd, v_brake, kappa_ff],
                                      dt_s)
        x_next = np.asarray(x_next).ravel()
        s_next = float(s_next)
        if s_next >= course.length_m:
            finish = t + dt_s * (course.length_m - s) / max(s_next - s, 1e-9)
            x, s, t, y = x_next, course.length_m, t + dt_s, np.asarray(y_next).ravel()
            rows.append((t, s, x[0], x[4], y[0], x[7] * truth_rider.w_prime_j, y[3]))
            break
        x, s, t, y = x_next, s_next, t + dt_s, np.asarray(y_next).ravel()
    bar.close()
    if engine is not None:
        engine.close()
    arr = np.array(rows)
    return SimResult(
        scenario=scenario, policy=policy, t_s=arr[:, 0], s_m=arr[:, 1], n_m=arr[:, 2],
        v_mps=arr[:, 3], power_w=arr[:, 4], w_prime_j=arr[:, 5], friction_use=arr[:, 6],
        samples=samples, advice=advice, finish_time_s=finish,
        solve_times_s=engine.solve_times_s if engine is not None else [],
        fallbacks=sum(a.fallback for a in advice),
        cp_in_use_w=engine.critical_power_w if engine is not None else math.nan,
    )


_STEPS: dict[RiderBehaviour, ca.Function] = {}


def _step_function(behaviour: RiderBehaviour) -> ca.Function:
    """The compiled closed-loop step (built once per behaviour)."""
    if behaviour not in _STEPS:
        _STEPS[behaviour] = _closed_loop_step(behaviour, substeps=5)
    return _STEPS[behaviour]


def _road(course: Course, s: float) -> list[float]:
    """The `model.ROAD` vector at `s`: curvature, slope, heading (ds unused in time)."""
    return [float(course.at("kappa_per_m", s)), float(course.at("beta_rad", s)),
            float(course.at("theta_rad", s)), 1.0]


def compare_policies(course: Course, rider: Rider, plan: Plan, *,
                     scenario: Scenario | str = Scenario.NOMINAL, seed: int = 0,
                     conditions: Conditions = Conditions(),
                     engine_settings: EngineSettings = EngineSettings(),
                     planner: object | None = None,
                     behaviour: RiderBehaviour = RiderBehaviour(),
                     **kwargs: object) -> dict[str, object]:
    """The three policies on the same truth, and the figures `itt-planner simulate` prints.

    `behaviour` and `kwargs` go to `simulate_ride` (sensors, scenario settings, dt_s).
    Margins are positive when the replanned ride is faster. `plan_finish_time_s` is the
    full-course optimum for the conditions `plan` was solved for: for the grip the
    rider uses when those are `planning_conditions` (`plan_for_rider_grip` says whether
    they are, from the plan's metadata; a plan cornering at full grip is one this
    rider cannot follow).

    Raises:
        IttError: unknown scenario.
    """
    runs = {policy: simulate_ride(course, rider, plan, scenario=scenario, seed=seed,
                                  policy=policy, conditions=conditions,
                                  engine_settings=engine_settings, planner=planner,
                                  behaviour=behaviour, **kwargs)  # type: ignore[arg-type]
            for policy in Policy}
    replanned = runs[Policy.REPLANNED]
    lat = np.array(replanned.solve_times_s) if replanned.solve_times_s else np.zeros(1)
    t_re = replanned.finish_time_s
    believed = dataclasses.asdict(planning_conditions(conditions, behaviour))
    return {
        "course": course.name, "rider": rider.name, "scenario": Scenario(scenario).value,
        "seed": seed,
        "plan_finish_time_s": round(plan.finish_time_s, 3),
        "plan_for_rider_grip": plan.meta.get("conditions") == believed,
        **{p.value: runs[p].summary() for p in Policy},
        "margins": {
            "replanned_vs_open_loop_s": round(runs[Policy.OPEN_LOOP].finish_time_s - t_re, 3),
            "replanned_vs_even_cp_s": round(runs[Policy.EVEN_CP].finish_time_s - t_re, 3),
            "replanned_vs_plan_pct": round(100 * (t_re / plan.finish_time_s - 1), 3),
        },
        "replan_latency_s": {"median": round(float(np.median(lat)), 4),
                             "p95": round(float(np.percentile(lat, 95)), 4),
                             "max": round(float(lat.max()), 4)},
        "replans": len(replanned.solve_times_s),
    }
