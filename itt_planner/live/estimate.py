"""State estimation: stamped GPS, wheel speed and power -> `RiderState` on a `Course`.

Progress `s` and speed `v` come from a two-state Kalman filter (constant-velocity
process): wheel speed measures `v`, and each GPS fix, map-matched to the course, measures
`s`. Map matching is LOCAL: a fix is projected onto the centre line only within a window
around the predicted `s` (courses cross themselves, so a global nearest point would jump
to the wrong branch); a fix whose innovation fails a chi-square gate (a 100 m jump) or
that lies far off the road is rejected and counted. After several consecutive rejections
the estimator is "lost" and re-acquires globally. Without GPS (tunnels, dropouts) the
filter dead-reckons on wheel speed; its `s` variance grows so the returning fixes are
accepted and pull it back.

The published `s` never moves backwards: it follows the filter with a bounded forward
catch-up and, when the filter falls behind it, slows down instead of jumping back. On a
closed loop the map matching wraps around the seam; progress is cumulative and the
published `s_m` is clipped at the course length (the ride is done there).

W' balance is integrated from measured power with `wprime.e_n_rate` (model.md E9, Skiba
by default), holding each reading until the next one for at most `power_hold_s`, with
the critical power in use (`rider`). The published balance (`state`) is never below 0:
a balance that would go below is the belief being wrong, which the pacing engine
corrects by refitting CP (`fit_critical_power`, `use_critical_power`; `cp_monitor`).

Bad inputs (NaN or negative values, time going backwards, duplicate stamps, fixes far
off the course) are dropped with a logged warning and counted in `counters`; nothing
here raises on input data.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.model.rider import Rider
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.model.state import RiderState
from itt_planner.model.wprime import WPrimeModel, e_n_rate

log = logging.getLogger(__name__)

#: Passes of the road whose distances to a fix differ by less than this are ambiguous
#: for a global match (GPS noise is 3-5 m; a hairpin's legs are ~2 radii apart).
_AMBIGUOUS_M = 8.0


@dataclass(frozen=True)
class EstimatorSettings:
    """Noise levels, gates and limits of the estimator (SI units).

    Attributes:
        gps_std_m: GPS 1-sigma used when a fix carries none (bike GPS: 3-5 m).
        speed_std_mps: wheel-speed noise.
        accel_std_mps2: process noise, the rider's unmodelled acceleration.
        odometry_drift: dead-reckoning error as a fraction of the distance travelled
            (wheel circumference error, the wheel speed measuring the bicycle's path
            rather than the centre line).
        gate_sigma: a GPS `s` innovation beyond this many sigmas is an outlier ...
        gate_floor_m: ... unless it is smaller than this (so a confident filter still
            accepts ordinary GPS noise).
        off_course_m: a fix farther than this beyond the road edge is off the course.
        search_margin_m: the local search window is predicted `s` +/- (this + 4 sigma).
        lost_after: this many consecutive rejected fixes trigger a global re-acquisition.
        speed_stale_s: wheel speed older than this is not trusted for dead reckoning:
            the speed then decays (a stopped or sensorless rider) instead of running on.
        speed_decay_s: time constant of that decay.
        power_hold_s: a power reading holds at most this long; beyond it power counts as 0.
        max_power_w: readings above this are spikes.
        max_speed_mps: wheel speeds above this are glitches.
        max_lag_s: a sample older than the filter time by more than this is dropped
            (samples of different topics may interleave slightly out of order).
        catchup_mps: how fast the published `s` may catch up with the filter, beyond
            the speed itself.
        lateral_tau_s: time constant of the lateral offset low-pass: bike GPS cannot
            place a rider within a lane (its 3-5 m error is a slowly wandering bias), so
            `n` is only a slow, conservative estimate ...
        lateral_edge_m: ... kept this far inside the road edges (a noisy `n` at the
            edge would make the planner brake for a road edge the rider is not at).
        global_window_m: a local search window wider than this (after a long gap)
            becomes a global search that prefers the predicted `s`.
        wprime_model: E9 variant.
    """

    gps_std_m: float = 4.0
    speed_std_mps: float = 0.3
    accel_std_mps2: float = 0.7
    odometry_drift: float = 0.03
    gate_sigma: float = 4.0
    gate_floor_m: float = 20.0
    off_course_m: float = 30.0
    search_margin_m: float = 60.0
    lost_after: int = 5
    speed_stale_s: float = 3.0
    speed_decay_s: float = 2.0
    power_hold_s: float = 5.0
    max_power_w: float = 3000.0
    max_speed_mps: float = 35.0
    max_lag_s: float = 2.0
    catchup_mps: float = 5.0
    lateral_tau_s: float = 10.0
    lateral_edge_m: float = 1.0
    global_window_m: float = 2000.0
    wprime_model: WPrimeModel = WPrimeModel.SKIBA


@dataclass(frozen=True)
class Match:
    """A fix projected on the centre line: arc length, signed offset (left +)."""

    s_m: float
    n_m: float


class StateEstimator:
    """Fuses stamped samples into a `RiderState`. Not thread-safe (the engine locks it).

    Args:
        course: the course to map-match on.
        rider: critical power and W' for the balance (E9).
        settings: noise levels and gates.
    """

    def __init__(self, course: Course, rider: Rider,
                 settings: EstimatorSettings = EstimatorSettings()) -> None:
        self.course = course
        self.rider = rider
        self.settings = settings
        self.counters: Counter[str] = Counter()
        # Closed loops repeat: the last grid point duplicates the first.
        self._period_m = course.length_m if course.closed_loop else math.inf
        self._t: float | None = None  # filter time (stamp of the last prediction)
        self._x = np.zeros(2)  # [s cumulative, v]
        self._p = np.eye(2)
        self._s_pub = 0.0
        self._n = 0.0
        self._start_s: float | None = None
        self._last_stamp: dict[str, float] = {}
        self._speed_t = -math.inf  # stamp of the last accepted wheel speed
        self._rejected_run: list[GpsFix] = []
        self._gps_t = -math.inf
        self._e_n = 1.0
        self._power_t: float | None = None
        self._power_w = 0.0
        #: Accepted power readings (stamp, W) since the start or a restore, and W' then:
        #: what `refit_critical_power` replays.
        self._power_log: list[tuple[float, float]] = []
        self._e_n_log_start = 1.0

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
        theta = float(self.course.at("theta_rad", self._wrap(s_m)))
        return RiderState(
            stamp_s=t, s_m=s_m, n_m=self._n, speed_mps=float(max(self._x[1], 0.0)),
            heading_rad=theta, power_w=self._power_now(t),
            w_prime_j=max(self._e_n_at(t), 0.0) * self.rider.w_prime_j,
            elapsed_s=t - self._start_s,
            gps_fresh=t - self._gps_t <= 3.0,
        )

    @property
    def s_std_m(self) -> float:
        """1-sigma of the filter's arc length."""
        return float(math.sqrt(self._p[0, 0]))

    def snapshot(self) -> dict[str, Any]:
        """Progress and W' balance, JSON-serialisable, for a node restart."""
        e_n = self._e_n_at(self._t) if self._t is not None else self._e_n
        return {"s_m": self._s_pub, "w_prime_j": e_n * self.rider.w_prime_j,
                "start_stamp_s": self._start_s, "stamp_s": self._t}

    def restore(self, snap: dict[str, Any]) -> None:
        """Resume from `snapshot()`: W' and the start time are kept, and the next GPS
        fix is matched around the saved progress (no backward jump on restart).

        Raises:
            KeyError: a field of the snapshot is missing.
        """
        self._e_n = float(snap["w_prime_j"]) / self.rider.w_prime_j
        self._start_s = snap["start_stamp_s"]
        self._s_pub = float(snap["s_m"])
        self._x = np.array([self._s_pub, 0.0])
        self._p = np.diag([self.settings.search_margin_m ** 2, 4.0])
        self._t = snap["stamp_s"]
        self._power_t = snap["stamp_s"]
        self._power_w = 0.0
        self._power_log = []
        self._e_n_log_start = self._e_n

    # ---- inputs -------------------------------------------------------------------------
    def on_gps(self, fix: GpsFix) -> bool:
        """Map-match a fix and correct `s` (and `n`). Returns False if it was rejected."""
        if not all(map(math.isfinite, (fix.stamp_s, fix.lat_deg, fix.lon_deg))) or \
                abs(fix.lat_deg) > 90 or abs(fix.lon_deg) > 180:
            return self._reject("gps_invalid", fix)
        if not self._accept_stamp("gps", fix.stamp_s):
            return False
        alt = fix.alt_m if math.isfinite(fix.alt_m) else self.course.origin.alt_m
        x, y, _ = self.course.from_geodetic(fix.lat_deg, fix.lon_deg, alt)
        std = fix.std_m if math.isfinite(fix.std_m) and fix.std_m > 0 else \
            self.settings.gps_std_m
        if self._t is None:
            match = self._global_match(float(x), float(y), prefer_s=0.0)
            if match is None:
                return self._reject("gps_off_course", fix)
            self._init(fix.stamp_s, match, std)
            return True
        self._predict(fix.stamp_s)
        match = self._local_match(float(x), float(y))
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
        if not self._accept_stamp("power", sample.stamp_s):
            return False
        self._mark_start(sample.stamp_s)
        if self._power_t is not None:
            self._e_n = self._e_n_at(sample.stamp_s)
        self._power_t = sample.stamp_s
        self._power_w = p
        self._power_log.append((sample.stamp_s, p))
        self.counters["power_accepted"] += 1
        return True

    def refit_critical_power(self, w_prime_now_j: float = 0.0) -> float:
        """`fit_critical_power` over [0.5 CP, CP] and carry on with it (`use_critical_power`).

        Why: a rider who cannot hold a target above CP has run out of W' while the
        balance at the believed CP still shows some: CP was overestimated (a W' deficit
        is far more likely than a wrong W'). Never raises CP here.

        Returns:
            The critical power now used (W).
        """
        cp = self.fit_critical_power(0.5 * self.rider.critical_power_w,
                                     self.rider.critical_power_w, w_prime_now_j)
        if cp < self.rider.critical_power_w:
            self.use_critical_power(cp)
        return self.rider.critical_power_w

    def fit_critical_power(self, low_w: float, high_w: float,
                           w_prime_j: float = 0.0) -> float:
        """The critical power in [low_w, high_w] at which the lowest W' balance over the
        power history is `w_prime_j` (E9, the history replayed from the start or the
        last restore; bisection to ~0.01 W). `high_w` when even that CP's balance gets
        that low, `low_w` when even that CP's stays above. Changes nothing.

        A higher CP gives a higher balance everywhere, so this is at once the highest CP
        whose balance empties (a rider out of W': the whole shortfall is not blamed on
        the detection window, where the rider has been empty a while) and the lowest
        whose balance never goes below it (a rider who did more than the belief allows).
        """
        if len(self._power_log) < 2:
            return self.rider.critical_power_w
        target = w_prime_j / self.rider.w_prime_j
        lo, hi = low_w, high_w
        if self._history_balance(hi)[0] <= target:
            return hi
        if self._history_balance(lo)[0] >= target:
            return lo
        for _ in range(25):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self._history_balance(mid)[0] < target else (lo, mid)
        return hi

    def use_critical_power(self, cp_w: float) -> None:
        """Carry on with critical power `cp_w`: the balance now is that of the whole
        power history replayed with it."""
        self.rider = dataclasses.replace(self.rider, critical_power_w=cp_w)
        if len(self._power_log) >= 2:
            self._e_n = self._history_balance(cp_w)[1]
            self._power_t, self._power_w = self._power_log[-1]

    def w_prime_raw_j(self, stamp_s: float) -> float:
        """The W' balance at `stamp_s` as integrated, below zero when the rider has done
        more than the CP in use allows (`state` shows it clipped at 0)."""
        return self._e_n_at(stamp_s) * self.rider.w_prime_j

    def _history_balance(self, cp_w: float) -> tuple[float, float]:
        """(lowest, last) normalised W' over the power history with CP `cp_w`."""
        stamps = np.array([s for s, _ in self._power_log])
        powers = np.array([p for _, p in self._power_log])
        dt = np.minimum(np.diff(stamps), self.settings.power_hold_s)
        e = low = self._e_n_log_start
        w0 = self.rider.w_prime_j
        for p, h in zip(powers[:-1].tolist(), dt.tolist()):
            # Skiba E9 (`wprime.e_n_rate`), written out on floats: this loop runs over
            # the whole ride ~25 times per fit.
            if p > cp_w:
                e -= (p - cp_w) / w0 * h
            elif self.settings.wprime_model is WPrimeModel.SKIBA:
                e = min(e + (cp_w - p) * (1 - e) / w0 * h, 1.0)
            else:
                e = min(e + float(e_n_rate(e, p, cp_w, w0, self.settings.wprime_model)) * h, 1.0)
            low = min(low, e)
        return low, e

    # ---- stamps and counters ------------------------------------------------------------
    def _reject(self, reason: str, sample: object) -> bool:
        self.counters[reason] += 1
        log.warning("estimator: rejected %s (%s), %d so far", sample, reason,
                    self.counters[reason])
        return False

    def _accept_stamp(self, topic: str, stamp: float) -> bool:
        last = self._last_stamp.get(topic)
        if last is not None and stamp == last:
            return self._reject(f"{topic}_duplicate_stamp", stamp)
        if last is not None and stamp < last:
            return self._reject(f"{topic}_time_backwards", stamp)
        if self._t is not None and stamp < self._t - self.settings.max_lag_s:
            return self._reject(f"{topic}_too_late", stamp)
        self._last_stamp[topic] = stamp
        return True

    def _mark_start(self, stamp: float) -> None:
        if self._start_s is None:
            self._start_s = stamp

    # ---- Kalman filter on (s, v) ----------------------------------------------------------
    def _init(self, stamp: float, match: Match, std: float) -> None:
        self._mark_start(stamp)
        self._t = stamp
        self._x = np.array([match.s_m, self._x[1]])
        self._p = np.diag([std * std, 4.0])
        self._s_pub = match.s_m
        self._n = match.n_m
        self._gps_t = stamp
        self.counters["gps_accepted"] += 1

    def _predict(self, stamp: float) -> None:
        """Advance the filter and the published `s` to `stamp` (no-op if not later)."""
        assert self._t is not None
        dt = stamp - self._t
        if dt <= 0:
            return
        st = self.settings
        v = self._x[1]
        if stamp - self._speed_t > st.speed_stale_s:
            # No fresh wheel speed: do not run on at the last speed through a long gap.
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
        return abs(innovation) <= max(self.settings.gate_sigma * sigma,
                                      self.settings.gate_floor_m)

    def _update_lateral(self, n: float, stamp: float) -> None:
        dt = stamp - self._gps_t if math.isfinite(self._gps_t) else 1.0
        k = min(1.0, max(dt, 0.0) / self.settings.lateral_tau_s)
        s = self._wrap(min(self._s_pub, self.course.length_m))
        wl = float(self.course.at("width_left_m", s))
        wr = float(self.course.at("width_right_m", s))
        edge = self.settings.lateral_edge_m
        self._n = float(np.clip(self._n + k * (n - self._n), -wr + edge, wl - edge))

    def _reacquire(self, x: float, y: float, std: float) -> bool:
        """Lost: several fixes in a row rejected. Match the latest one globally."""
        self.counters["gps_reacquire_attempts"] += 1
        match = self._global_match(x, y, prefer_s=self._x[0])
        if match is None:
            return self._reject("gps_off_course", "lost, no course point near the fix")
        log.warning("estimator: lost for %d fixes, re-acquired at s=%.0f m (filter had %.0f m)",
                    len(self._rejected_run), match.s_m, self._x[0])
        self.counters["gps_reacquired"] += 1
        self._rejected_run.clear()
        self._x[0] = match.s_m
        # The old estimate was wrong, not noisy: jump forward now rather than catch up.
        # (Backwards, the published s still never moves back: it slows until passed.)
        self._s_pub = max(self._s_pub, match.s_m)
        self._p[0, 0] = std * std
        self._p[0, 1] = self._p[1, 0] = 0.0
        self._n = match.n_m
        return True

    # ---- map matching -------------------------------------------------------------------
    def _wrap(self, s: float) -> float:
        return s % self._period_m if math.isfinite(self._period_m) else s

    def _project(self, idx: np.ndarray, x: float, y: float) -> tuple[int, float, float]:
        """Nearest grid point among `idx`, refined onto its tangent: (index, ds, n)."""
        c = self.course
        d2 = (c.x_m[idx] - x) ** 2 + (c.y_m[idx] - y) ** 2
        i = int(idx[int(np.argmin(d2))])
        dx, dy = x - c.x_m[i], y - c.y_m[i]
        th = c.theta_rad[i]
        along = float(np.clip(dx * math.cos(th) + dy * math.sin(th), -c.ds_m, c.ds_m))
        return i, along, float(-dx * math.sin(th) + dy * math.cos(th))

    def _local_match(self, x: float, y: float) -> Match | None:
        """Project within the window around the predicted `s`; None when off the road."""
        c = self.course
        half = self.settings.search_margin_m + 4 * math.sqrt(self._p[0, 0])
        s_pred = self._x[0]
        if half > self.settings.global_window_m:
            # So uncertain (a long gap) that a local window means little: search globally.
            return self._global_match(x, y, prefer_s=s_pred)
        lo, hi = s_pred - half, s_pred + half
        n_grid = len(c.s_m)
        if math.isfinite(self._period_m):
            period_pts = n_grid - 1
            half_pts = min(int(half / c.ds_m), period_pts // 2)
            centre = int(round(s_pred / c.ds_m))
            idx = np.arange(centre - half_pts, centre + half_pts + 1)
            lap_idx = idx  # unwrapped index: lap count in its multiples of the period
            idx = np.mod(idx, period_pts)
        else:
            i0 = max(int(math.floor(lo / c.ds_m)), 0)
            i1 = min(int(math.ceil(hi / c.ds_m)), n_grid - 1)
            if i1 < i0:
                return None
            idx = lap_idx = np.arange(i0, i1 + 1)
        i, along, n = self._project(idx, x, y)
        k = int(np.flatnonzero(idx == i)[0])
        s = float(lap_idx[k] * c.ds_m + along)
        if not self._on_road(i, n):
            return None
        return Match(s, n)

    def _on_road(self, i: int, n: float) -> bool:
        c = self.course
        limit = c.width_left_m[i] if n > 0 else c.width_right_m[i]
        return abs(n) <= limit + self.settings.off_course_m

    def _global_match(self, x: float, y: float, prefer_s: float) -> Match | None:
        """The whole course: the pass nearest the fix; if several are about as near,
        the one nearest `prefer_s`.

        Where the road passes the fix several times (a crossing, a hairpin's two legs,
        start = finish), each pass is a separate run of close grid points. Passes within
        `_AMBIGUOUS_M` of the nearest are ties; among them the arc length closest to
        `prefer_s` (ties broken towards progress) wins.
        """
        c = self.course
        d = np.hypot(c.x_m - x, c.y_m - y)
        close = d <= np.maximum(c.width_left_m, c.width_right_m) + self.settings.off_course_m
        if not close.any():
            return None
        edges = np.flatnonzero(np.diff(np.concatenate([[0], close.astype(int), [0]])))
        base = 0.0
        if math.isfinite(self._period_m):
            base = math.floor(prefer_s / self._period_m) * self._period_m
        passes: list[Match] = []
        for a, b in zip(edges[::2], edges[1::2]):
            i, along, n = self._project(np.arange(a, b), x, y)
            s = base + c.s_m[i] + along
            if math.isfinite(self._period_m) and s < prefer_s - self._period_m / 2:
                s += self._period_m
            passes.append(Match(float(s), n))
        nearest = min(abs(m.n_m) for m in passes)
        ties = [m for m in passes if abs(m.n_m) <= nearest + _AMBIGUOUS_M]
        return min(ties, key=lambda m: abs(m.s_m - prefer_s) + (0.0 if m.s_m >= prefer_s else 1.0))

    # ---- W' balance ---------------------------------------------------------------------
    def _power_now(self, t: float) -> float:
        if self._power_t is None or t - self._power_t > self.settings.power_hold_s:
            return 0.0
        return self._power_w

    def _e_n_at(self, t: float) -> float:
        """Normalised W' at `t` >= the last reading, the last power held (E9, Euler
        steps of at most 1 s: the balance changes by < 1 % of W' per second)."""
        if self._power_t is None or t <= self._power_t:
            return self._e_n
        r = self.rider
        e = self._e_n
        held = min(t - self._power_t, self.settings.power_hold_s)
        for span, power in ((held, self._power_w), (t - self._power_t - held, 0.0)):
            steps = int(math.ceil(span))
            for _ in range(steps):
                rate = float(e_n_rate(e, power, r.critical_power_w, r.w_prime_j,
                                      self.settings.wprime_model))
                e = min(e + rate * span / steps, 1.0)
        return e
