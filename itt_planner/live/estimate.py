"""State estimation: stamped samples -> `RiderState` on a `Course` (a Kalman filter).

Progress `s` and speed `v` come from a two-state Kalman filter (constant-velocity
process): wheel speed measures `v`, and each GPS fix, map-matched to the course
(`map_match`: locally, around the predicted `s`), measures `s`. A fix whose innovation
fails a chi-square gate (a 100 m jump) or that lies far off the road is rejected and
counted. After several consecutive rejections the estimator is "lost" and re-acquires
globally. Without GPS (tunnels, dropouts) the filter dead-reckons on wheel speed; its `s`
variance grows so the returning fixes are accepted and pull it back. Without wheel speed
the fixes alone measure `v`; without either, `v` decays (a rider stopping).

The published `s` does not move backwards: it follows the filter with a bounded forward
catch-up and, when the filter falls behind it, slows down instead of jumping back. One
exception: a first fix away from the start places the rider where it matches, but until
the rider has ridden `confirm_m` on from there, that placement is a guess; a
re-acquisition meanwhile looks for the start first and, found far behind
(`reacquire_back_m`), moves the published `s` back to it (a ride logged from before the
start, whose first fixes matched the road the course finishes on, was otherwise advised
"finished" for the rest of the ride: the GoldenCheetah Boise ride, 2026-12-04).

On a closed loop the map matching wraps around the seam; progress is cumulative and the
published `s_m` is clipped at the course length (the ride is done there).

Power readings go to the engine's W' model (`wprime_balance.WPrimeBalance`, the one
holder of the CP in use), which the state reports (power held, W' balance).

Each sensor has ONE hook here (`on_gps`, `on_speed`, `on_power`), listed with its sensor
name in `StateEstimator.hooks`: the engine dispatches every sample through that table.
Adding a sensor is one hook and one line in it.

Bad inputs (NaN or negative values, time going backwards, duplicate stamps, fixes far
off the course) are dropped, logged and counted in `counters`; nothing here raises.
"""

from __future__ import annotations

import logging
import math
from collections import Counter, deque
from collections.abc import Callable
from typing import Any

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.live.estimator_settings import EstimatorSettings
from itt_planner.live.map_match import MapMatcher, Match
from itt_planner.live.samples import GpsFix, PowerReading, Sample, WheelSpeed
from itt_planner.live.wprime_balance import WPrimeBalance
from itt_planner.model.state import RiderState

log = logging.getLogger(__name__)

#: A sensor's hook: takes a sample of its type, returns whether it was accepted.
Hook = Callable[[Any], bool]


class StateEstimator:
    """Fuses stamped samples into a `RiderState`. Not thread-safe (the engine locks it).

    Args:
        course: the course to map-match on.
        balance: the W' model the power readings go to (the engine's).
        settings: noise levels and gates (`power_hold_s` and `wprime_model` are for
            the balance the engine builds).
    """

    def __init__(self, course: Course, balance: WPrimeBalance,
                 settings: EstimatorSettings = EstimatorSettings()) -> None:
        self.course = course
        self.balance = balance
        self.settings = settings
        self.counters: Counter[str] = Counter()
        self._matcher = MapMatcher(course, settings.search_margin_m, settings.global_window_m,
                                   settings.off_course_m)
        self._t: float | None = None  # filter time (stamp of the last prediction)
        self._x = np.zeros(2)  # [s cumulative, v]
        self._p = np.eye(2)
        self._s_pub = 0.0
        self._n = 0.0
        self._start_s: float | None = None
        # Where the first fix placed the rider, until the rider has ridden on from there.
        self._placed_s: float | None = None
        self._last_stamp: dict[str, float] = {}
        self._speed_t = -math.inf  # stamp of the last accepted wheel speed
        self._rejected_run: list[GpsFix] = []
        self._gps_t = -math.inf
        # Intervals between accepted fixes: how long without one is a dropout.
        self._fix_intervals: deque[float] = deque(maxlen=settings.gps_intervals_kept)
        #: The per-sensor hooks: sample type -> (sensor name, hook). The name keys the
        #: counters, the stamp checks and the engine's input diagnostics.
        self.hooks: dict[type, tuple[str, Hook]] = {
            GpsFix: ("gps", self.on_gps),
            WheelSpeed: ("speed", self.on_speed),
            PowerReading: ("power", self.on_power),
        }

    def hook(self, sample: Sample) -> tuple[str, Hook]:
        """The sensor name and the hook of a sample's type.

        Raises:
            TypeError: no hook for this sample type.
        """
        found = self.hooks.get(type(sample))
        if found is None:
            raise TypeError(f"the estimator has no hook for {type(sample).__name__}")
        return found

    # ---- public queries ----------------------------------------------------------------
    @property
    def initialised(self) -> bool:
        """True once a GPS fix has placed the rider on the course."""
        return self._t is not None

    @property
    def stamp_s(self) -> float | None:
        """Filter time: the stamp of the latest sample that moved it (None before)."""
        return self._t

    @property
    def distance_m(self) -> float:
        """Published cumulative progress (laps included on a closed loop)."""
        return self._s_pub

    def state(self, stamp_s: float) -> RiderState | None:
        """The state at `stamp_s` (predicted forward from the last sample), or None.

        A stamp earlier than the last sample gives the state at the last sample.
        """
        if self._t is None or self._start_s is None:
            return None
        if stamp_s > self._t:
            self._predict(stamp_s)
        t = self._t
        s_m = min(self._s_pub, self.course.length_m)
        theta = float(self.course.at("theta_rad", self._matcher.wrap(s_m)))
        return RiderState(
            stamp_s=t, s_m=s_m, n_m=self._n, speed_mps=float(max(self._x[1], 0.0)),
            heading_rad=theta, power_w=self.balance.power_now(t),
            w_prime_j=self.balance.balance_j(t),
            elapsed_s=t - self._start_s,
            gps_fresh=t - self._gps_t <= 3.0,
        )

    @property
    def s_std_m(self) -> float:
        """1-sigma of the filter's arc length."""
        return float(math.sqrt(self._p[0, 0]))

    def snapshot(self) -> dict[str, Any]:
        """Progress and W' balance, JSON-serialisable, for a node restart."""
        return {"s_m": self._s_pub, "w_prime_j": self.balance.snapshot(self._t),
                "start_stamp_s": self._start_s, "stamp_s": self._t}

    def restore(self, snap: dict[str, Any]) -> None:
        """Resume from `snapshot()`: W' and the start time are kept, and the next GPS
        fix is matched around the saved progress (no backward jump on restart).

        Raises:
            KeyError: a field of the snapshot is missing.
        """
        self._start_s = snap["start_stamp_s"]
        self._placed_s = None  # the saved progress was ridden, not guessed
        self._s_pub = float(snap["s_m"])
        self._x = np.array([self._s_pub, 0.0])
        self._p = np.diag([self.settings.search_margin_m ** 2, 4.0])
        self._t = snap["stamp_s"]
        self.balance.restore(float(snap["w_prime_j"]), snap["stamp_s"])

    # ---- inputs -------------------------------------------------------------------------
    def on_gps(self, fix: GpsFix) -> bool:
        """Map-match a fix and correct `s` (and `n`). Returns False if it was rejected."""
        if not all(map(math.isfinite, (fix.stamp_s, fix.lat_deg, fix.lon_deg))) or \
                abs(fix.lat_deg) > 90 or abs(fix.lon_deg) > 180:
            return self._reject("gps_invalid", fix)
        if not self._accept_stamp("gps", fix.stamp_s):
            return False
        alt = fix.alt_m if math.isfinite(fix.alt_m) else self.course.origin.alt_m
        lat_lon_alt: tuple[Any, Any, Any] = (fix.lat_deg, fix.lon_deg, alt)  # floats do
        x, y, _ = self.course.from_geodetic(*lat_lon_alt)
        std = fix.std_m if math.isfinite(fix.std_m) and fix.std_m > 0 else \
            self.settings.gps_std_m
        if self._t is None:
            return self._first_fix(fix, float(x), float(y), std)
        self._predict(fix.stamp_s)
        match = self._matcher.local(float(x), float(y), self._x[0], self._p[0, 0])
        ok = match is not None and self._gate(match, std)
        if not ok:
            self._rejected_run.append(fix)
            if len(self._rejected_run) >= self.settings.lost_after:
                return self._reacquire(float(x), float(y), std)
            return self._reject("gps_outlier" if match is not None else "gps_off_course", fix)
        assert match is not None
        self._rejected_run.clear()
        self._update(np.array([1.0, 0.0]), match.s_m, std * std)
        self._update_lateral(match.n_m, fix.stamp_s)
        if math.isfinite(self._gps_t):
            self._fix_intervals.append(fix.stamp_s - self._gps_t)
        self._gps_t = fix.stamp_s
        self.counters["gps_accepted"] += 1
        return True

    def on_speed(self, sample: WheelSpeed) -> bool:
        """Wheel speed measures `v`. Returns False if it was rejected."""
        v = sample.speed_mps
        if not (math.isfinite(sample.stamp_s) and math.isfinite(v)) or v < 0 or \
                v > self.settings.max_speed_mps:
            return self._reject("speed_invalid", sample)
        if not self._accept_stamp("speed", sample.stamp_s):
            return False
        self._mark_start(sample.stamp_s)
        self._speed_t = sample.stamp_s
        if self._t is not None:
            self._predict(sample.stamp_s)
            self._update(np.array([0.0, 1.0]), v, self.settings.speed_std_mps ** 2)
        else:
            self._x[1] = v
        self.counters["speed_accepted"] += 1
        return True

    def on_power(self, sample: PowerReading) -> bool:
        """Integrate W' up to this reading with the previous power held (E9)."""
        p = sample.power_w
        if not (math.isfinite(sample.stamp_s) and math.isfinite(p)) or p < 0 or \
                p > self.settings.max_power_w:
            return self._reject("power_invalid", sample)
        # Late against the filter is fine: the balance integrates on its own time axis.
        if not self._accept_stamp("power", sample.stamp_s, against_filter=False):
            return False
        self._mark_start(sample.stamp_s)
        self.balance.add(sample.stamp_s, p)
        self.counters["power_accepted"] += 1
        return True

    # ---- stamps and counters ------------------------------------------------------------
    def _reject(self, reason: str, sample: object) -> bool:
        self.counters[reason] += 1
        log.warning("estimator: rejected %s (%s), %d so far", sample, reason,
                    self.counters[reason])
        return False

    def _accept_stamp(self, topic: str, stamp: float, *, against_filter: bool = True) -> bool:
        """In order on its topic and, `against_filter`, not older than the filter time by
        more than `max_lag_s` (the filter only moves forward). Power is not held to the
        filter: a node whose power callbacks fell 2 s behind its GPS callback rejected 66
        readings (16 s at ~800 W) and its W' balance read 2.9 kJ high, off the plan."""
        last = self._last_stamp.get(topic)
        if last is not None and stamp == last:
            return self._reject(f"{topic}_duplicate_stamp", stamp)
        if last is not None and stamp < last:
            return self._reject(f"{topic}_time_backwards", stamp)
        if against_filter and self._t is not None and stamp < self._t - self.settings.max_lag_s:
            return self._reject(f"{topic}_too_late", stamp)
        self._last_stamp[topic] = stamp
        return True

    def _mark_start(self, stamp: float) -> None:
        if self._start_s is None:
            self._start_s = stamp

    # ---- Kalman filter on (s, v) ----------------------------------------------------------
    def _first_fix(self, fix: GpsFix, x: float, y: float, std: float) -> bool:
        """The first fix places the rider: at the start within reach, else on the course."""
        match = (self._matcher.start_match(x, y, self.settings.start_reach_m)
                 or self._matcher.nearest_pass(x, y, prefer_s=0.0))
        if match is None:
            return self._reject("gps_off_course", fix)
        self._init(fix.stamp_s, match, std)
        return True

    def _init(self, stamp: float, match: Match, std: float) -> None:
        self._mark_start(stamp)
        self._t = stamp
        self._x = np.array([match.s_m, self._x[1]])
        # Without a fresh wheel speed the speed is unknown until the next fixes tell.
        v_std = 2.0 if stamp - self._speed_t <= self.settings.speed_stale_s else 8.0
        self._p = np.diag([std * std, v_std ** 2])
        self._s_pub = match.s_m
        self._placed_s = match.s_m
        self._n = match.n_m
        self._gps_t = stamp
        self.counters["gps_accepted"] += 1

    def _gps_stale_s(self) -> float:
        """How long without a fix is a dropout: `gps_stale_s`, or longer for a recorder
        that writes fixes far apart (`EstimatorSettings.gps_interval_factor`)."""
        st = self.settings
        if len(self._fix_intervals) < 5:
            return st.gps_stale_s
        return max(st.gps_stale_s,
                   st.gps_interval_factor * float(np.percentile(self._fix_intervals, 90)))

    def _predict(self, stamp: float) -> None:
        """Advance the filter and the published `s` to `stamp` (no-op if not later)."""
        assert self._t is not None
        dt = stamp - self._t
        if dt <= 0:
            return
        st = self.settings
        v = self._x[1]
        if stamp - self._speed_t > st.speed_stale_s and stamp - self._gps_t > self._gps_stale_s():
            # No fresh speed nor fix: do not run on at the last speed through a long gap.
            decay = math.exp(-dt / st.speed_decay_s)
            ds = v * st.speed_decay_s * (1 - decay)
            self._x = np.array([self._x[0] + ds, v * decay])
            # The rider may have ridden on: let the returning GPS decide.
            self._p = self._p + np.diag([(st.max_speed_mps * dt) ** 2 / 4, 4.0])
        else:
            f = np.array([[1.0, dt], [0.0, 1.0]])
            q = st.accel_std_mps2 ** 2 * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
            q[0, 0] += (st.odometry_drift * abs(v) * dt) ** 2
            self._x = f @ self._x
            self._p = f @ self._p @ f.T + q
            ds = v * dt
        self._t = stamp
        self._advance_published(max(ds, 0.0), dt)

    def _update(self, h: np.ndarray, z: float, r: float) -> None:
        y = z - h @ self._x
        s = h @ self._p @ h + r
        k = self._p @ h / s
        self._x = self._x + k * y
        self._p = (np.eye(2) - np.outer(k, h)) @ self._p
        self._x[1] = max(self._x[1], 0.0)

    def _advance_published(self, ds: float, dt: float) -> None:
        """Move the published `s` by the predicted distance, corrected towards the filter
        at a bounded rate: forward by at most `catchup_mps`, backward never (at worst the
        published `s` advances at half the speed until the filter catches up)."""
        error = self._x[0] - (self._s_pub + ds)
        correction = min(max(error, -0.5 * ds), self.settings.catchup_mps * dt)
        self._s_pub += ds + correction

    def _gate(self, match: Match, std: float) -> bool:
        innovation = match.s_m - self._x[0]
        sigma = math.sqrt(self._p[0, 0] + std * std)
        return bool(abs(innovation) <= max(self.settings.gate_sigma * sigma,
                                           self.settings.gate_floor_m))

    def _update_lateral(self, n: float, stamp: float) -> None:
        dt = stamp - self._gps_t if math.isfinite(self._gps_t) else 1.0
        k = min(1.0, max(dt, 0.0) / self.settings.lateral_tau_s)
        s = self._matcher.wrap(min(self._s_pub, self.course.length_m))
        wl = float(self.course.at("width_left_m", s))
        wr = float(self.course.at("width_right_m", s))
        edge = self.settings.lateral_edge_m
        self._n = float(np.clip(self._n + k * (n - self._n), -wr + edge, wl - edge))

    def _reacquire(self, x: float, y: float, std: float) -> bool:
        """Lost: several fixes in a row rejected. Match the latest one globally."""
        self.counters["gps_reacquire_attempts"] += 1
        st = self.settings
        # Not yet away from the start, or not yet ridden on from where the first fix
        # placed the rider (module docstring): the start first.
        unproven = self._placed_s is not None and self._s_pub < self._placed_s + st.confirm_m
        at_start = self._s_pub < st.start_reach_m or unproven
        match = ((self._matcher.start_match(x, y, st.start_reach_m) if at_start else None)
                 or self._matcher.nearest_pass(x, y, prefer_s=0.0 if unproven else self._x[0]))
        if match is None:
            return self._reject("gps_off_course", "lost, no course point near the fix")
        log.warning("estimator: lost for %d fixes, re-acquired at s=%.0f m (filter had %.0f m)",
                    len(self._rejected_run), match.s_m, self._x[0])
        self.counters["gps_reacquired"] += 1
        self._rejected_run.clear()
        self._x[0] = match.s_m
        # The old estimate was wrong, not noisy: jump forward now rather than catch up;
        # backward only from a first placement not yet ridden on, when far behind it
        # (otherwise the published s slows until passed: a rider who rode there did).
        if unproven and match.s_m < self._s_pub - st.reacquire_back_m:
            log.warning("estimator: re-acquired %.0f m behind the published s=%.0f m, a "
                        "placement not yet ridden on: progress goes back to s=%.0f m",
                        self._s_pub - match.s_m, self._s_pub, match.s_m)
            self.counters["gps_reacquired_back"] += 1
            self._s_pub = self._placed_s = match.s_m  # a new guess, to be ridden on again
        else:
            self._s_pub = max(self._s_pub, match.s_m)
        self._p[0, 0] = std * std
        self._p[0, 1] = self._p[1, 0] = 0.0
        self._n = match.n_m
        return True
