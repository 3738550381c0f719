"""The critical-power belief, revised both ways from the power the rider delivers.

The W' balance (model.md E9) integrates measured power against the CP in use; when that
CP is wrong the balance drifts, and what the rider does reveals it, in two ways:

- DOWN, a rider out of W' the balance still shows: the rider WAS following advice
  above CP (delivering at least `follow_ratio` of the advised power, above CP, over the
  `follow_window_s` before), and then, over `window_s`, holds just below CP
  (`below_cp`), never surging above it (the `surge_quantile` of its power stays below
  CP: an exhausted rider cannot exceed CP, a rider easing off by choice does) and
  clearly short of the advice (`min_shortfall`), which stays clearly above CP
  (`above_cp`), while the balance still shows more than `min_w_prime` of W'.
  An exhausted rider holds what it still can, its true CP: the refitted CP is never
  below the power held (on the real Zwift Bologna ride a rider at 285 W against 303 W
  advised was refitted to 262 W from the history alone, and the balance at 262 W then
  went below zero 12 times; a 20 s dip to 267 W against 301 W advised, right after a
  minute at 295 W following it, was refitted to 268 W while the rider was back above
  330 W within 15 s: hence the 30 s window and the surge test), and a change under
  `min_change` is none.
  The surge test allows `surge_margin` above CP: power-meter noise around a rider at a
  true CP 5 % below the belief put the 90th percentile at or above the belief (the
  Riderman course, simulated: the refit came at 16.7 km of 17.2, its evidence was there
  at 5.0 km). Such a refit is only pending: it is adopted after `confirm_s` more in
  which no `surge_mean_s` mean of the power reached CP, and cancelled by one that did
  (the Zwift Bologna rider at 272 W against 308 W advised for 30 s, with no surge in
  them, was back at 331 W 4 s later).
  A rider who was NOT following (a steady ride below CP against higher advice, a hot
  start that ignores it) makes a choice, not a limit: no refit. (On a
  real ride the old detector, without the following condition, refitted 290 -> 263 W
  because the rider held 267 W for 20 s against 342 W with 9.7 kJ of W' left; the
  balance then ran to -24 kJ while the rider averaged 284 W for 31 min.)
- UP, a rider who has done more than the belief allows: the balance at the CP in use
  has gone below `-up_margin` x W' (so power-meter noise around an empty balance does
  not refit every second). The published balance is clipped at 0 meanwhile. The new CP
  is the lowest whose balance over the whole power history never goes below
  `up_margin` x W' (that headroom again, so that the next refit needs new evidence),
  but never above what the power held proves (`WPrimeBalance.proven_critical_power`:
  the best MMP(T) - W'/T over `up_durations_s`). Why: the balance goes below zero after
  a sprint too (W' or its recovery misjudged, not CP); on the Sauerland ride (CP 240 W
  calibrated) 1 s of 1,244 W and 1 s of 1,112 W at 78.8 km raised CP 291 -> 313 -> 343 W
  within 4 s, and on St John's 9 refits in 2.3 km made a staircase. When the power held
  proves no higher CP, the rider is `holding`: counted once per episode (`up_held`),
  logged, and in the diagnostic; the balance stays clipped at 0 until it recovers.

Down, the new CP is the one at which the lowest balance over the whole power history is
0 (`WPrimeBalance.fit_critical_power`): the highest CP whose balance empties. W' itself is kept (a
W' deficit is the likelier error over a time trial's 20-60 min; see the report).
Every refit is a `Refit` record with its evidence, a WARN diagnostic and a counter.
"""

from __future__ import annotations

import dataclasses
import logging
from collections import deque
from dataclasses import dataclass

import numpy as np

from itt_planner.live.advice import Diagnostic, Level
from itt_planner.live.wprime_balance import WPrimeBalance
from itt_planner.model.rider import Rider
from itt_planner.model.state import RiderState

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CpMonitorSettings:
    """Thresholds of the two refits (module docstring).

    Attributes:
        window_s: the shortfall is judged over this much stamp time ...
        above_cp: ... with the mean advice this fraction above the CP in use ...
        below_cp: ... and the mean power within this fraction below that CP ...
        min_shortfall: ... and at least this fraction below the mean advice ...
        surge_quantile, surge_margin: ... and this quantile of the power below CP
            times 1 + `surge_margin` ...
        min_w_prime: ... while the balance shows more than this fraction of W'.
        follow_window_s: before the shortfall window, the rider followed the advice
            over this much stamp time ...
        follow_ratio: ... delivering at least this fraction of the mean advised power,
            itself above CP (a rider lags the target by ~1 s and wanders a few %).
        confirm_s, surge_mean_s: such a refit is adopted after this much more stamp time
            in which no mean of the power over `surge_mean_s` reached CP; one that did
            cancels it (`down_cancelled`).
        up_margin: the balance at the CP in use this fraction of W' below zero raises CP
            (to the CP whose lowest balance is this fraction of W' above zero) ...
        up_durations_s: ... at most to what the power held over one of these durations
            proves (module docstring).
        min_change: a refit changing CP by less than this fraction is none (what a fit
            from 20 s of evidence can tell).
        up_factor, down_factor: the refitted CP is searched in [CP, up_factor CP] and
            [down_factor CP, CP].
    """

    window_s: float = 30.0
    above_cp: float = 0.05
    below_cp: float = 0.10
    min_shortfall: float = 0.10
    surge_quantile: float = 0.9
    surge_margin: float = 0.03
    min_w_prime: float = 0.05
    follow_window_s: float = 60.0
    follow_ratio: float = 0.90
    confirm_s: float = 10.0
    surge_mean_s: float = 5.0
    up_margin: float = 0.05
    # 10 s to 1 h, 5 % apart (a proof at a coarser step lags the balance's crossing).
    up_durations_s: tuple[float, ...] = tuple(sorted({float(round(10 * 1.05 ** k))
                                                      for k in range(122)}))
    min_change: float = 0.01
    up_factor: float = 1.5
    down_factor: float = 0.5


@dataclass(frozen=True)
class Refit:
    """One revision of the CP in use and its evidence.

    Attributes:
        direction: "down" (out of W' the balance still showed) or "up" (more done than
            the belief allows).
        power_held_w, target_w, duration_s: the mean measured and advised power over
            the evidence window and its length ("up": the best mean power over the
            duration that proves the new CP, `proven_critical_power`, and the mean
            advised power of the last window).
        w_prime_j: the balance at the old CP at that moment (below zero for "up").
    """

    stamp_s: float
    s_m: float
    direction: str
    cp_before_w: float
    cp_after_w: float
    power_held_w: float
    target_w: float
    duration_s: float
    w_prime_j: float

    def message(self) -> str:
        if self.direction == "down":
            why = (f"rider held {self.power_held_w:.0f} W against {self.target_w:.0f} W "
                   f"advised for {self.duration_s:.0f} s after following the advice, with "
                   f"{self.w_prime_j / 1000:.1f} kJ of W' left at the old CP, and no surge "
                   "to it since: out of W'")
        else:
            why = (f"rider held {self.power_held_w:.0f} W over {self.duration_s:.0f} s "
                   f"and the balance at the old CP reached {self.w_prime_j / 1000:.1f} kJ: "
                   "more than the belief allows")
        return (f"CP refitted {self.direction} {self.cp_before_w:.0f} -> {self.cp_after_w:.0f} W "
                f"at {self.s_m / 1000:.2f} km (stamp {self.stamp_s:.0f} s): {why}")

    def values(self) -> dict[str, str]:
        return {"direction": self.direction, "stamp_s": f"{self.stamp_s:.1f}",
                "s_m": f"{self.s_m:.0f}", "cp_before_w": f"{self.cp_before_w:.1f}",
                "cp_after_w": f"{self.cp_after_w:.1f}",
                "power_held_w": f"{self.power_held_w:.1f}", "target_w": f"{self.target_w:.1f}",
                "duration_s": f"{self.duration_s:.0f}", "w_prime_j": f"{self.w_prime_j:.0f}"}


class CpMonitor:
    """Watches (advised, measured) power and revises the CP in use (module docstring).

    Not thread-safe: the engine calls it with its lock held.

    Args:
        rider: the rider as first believed (W', the believed CP).
        balance: the engine's W' model: the CP in use, the balance and the power
            history (`fit_critical_power`).
        settings: thresholds.
    """

    def __init__(self, rider: Rider, balance: WPrimeBalance,
                 settings: CpMonitorSettings = CpMonitorSettings()) -> None:
        self.rider = rider
        self.balance = balance
        self.settings = settings
        self.refits: list[Refit] = []
        #: The balance is below the up margin but the power held proves no higher CP.
        self.holding = False
        #: Such episodes so far.
        self.up_held = 0
        #: A down-refit waiting for its confirmation, and those a surge cancelled.
        self._pending: Refit | None = None
        self.down_cancelled = 0
        #: (stamp, advised power, measured power) at every advice.
        self._rows: deque[tuple[float, float, float]] = deque()

    @property
    def cp_in_use_w(self) -> float:
        """The CP in use (the balance's)."""
        return self.balance.cp_w

    def observe(self, stamp_s: float, state: RiderState, target_w: float) -> Refit | None:
        """Record what was advised (the target the rider was shown) and delivered; refit
        when the evidence says so. Returns the refit, if any."""
        st = self.settings
        rows = self._rows
        rows.append((stamp_s, target_w, state.power_w))
        while rows and rows[0][0] < stamp_s - st.window_s - st.follow_window_s:
            rows.popleft()
        if refit := self._check_up(stamp_s, state):
            return refit
        if self._pending is not None:
            return self._confirm_down(stamp_s, state)
        self._pending = self._check_down(stamp_s, state)
        return None

    def _check_up(self, stamp_s: float, state: RiderState) -> Refit | None:
        st = self.settings
        cp = self.cp_in_use_w
        w_raw = self.balance.raw_j(stamp_s)
        if w_raw >= -st.up_margin * self.rider.w_prime_j:
            self.holding = False
            return None
        proven, over_s, held_w = self.balance.proven_critical_power(st.up_durations_s)
        if proven < cp * (1 + st.min_change):  # before the bisection: it replays the ride
            if not self.holding:
                self.up_held += 1
                log.warning("cp_monitor: the balance at CP %.0f W reached %.1f kJ at %.2f km, "
                            "but the power held proves no higher CP (at best %.0f W over "
                            "%.0f s: %.0f W): W' shown as 0, CP kept", cp, w_raw / 1000,
                            state.s_m / 1000, held_w, over_s, proven)
            self.holding = True
            return None
        self.holding = False
        new_cp = min(self.balance.fit_critical_power(cp, st.up_factor * cp,
                                                       st.up_margin * self.rider.w_prime_j),
                     proven)
        span = np.array(list(self._rows))
        return self._adopt(Refit(stamp_s, state.s_m, "up", cp, new_cp, held_w,
                                 float(span[:, 1].mean()), over_s, w_raw))

    def _check_down(self, stamp_s: float, state: RiderState) -> Refit | None:
        """The down-refit the last `window_s` call for (module docstring), to confirm."""
        st = self.settings
        rows = np.array(self._rows)
        if len(rows) < 3 or rows[-1, 0] - rows[0, 0] < 0.9 * (st.window_s + st.follow_window_s):
            return None
        recent = rows[rows[:, 0] >= stamp_s - st.window_s]
        before = rows[rows[:, 0] < stamp_s - st.window_s]
        cp = self.cp_in_use_w
        mean_target, mean_power = float(recent[:, 1].mean()), float(recent[:, 2].mean())
        if (mean_target < cp * (1 + st.above_cp)
                or not cp * (1 - st.below_cp) <= mean_power < cp
                or mean_power > (1 - st.min_shortfall) * mean_target
                or float(np.quantile(recent[:, 2], st.surge_quantile))
                >= cp * (1 + st.surge_margin)
                or state.w_prime_j < st.min_w_prime * self.rider.w_prime_j):
            return None
        followed_target, followed_power = float(before[:, 1].mean()), float(before[:, 2].mean())
        if not (followed_target > cp and followed_power > cp
                and followed_power >= st.follow_ratio * followed_target):
            log.info("cp_monitor: rider holds %.0f W against %.0f W advised but did not follow "
                     "the advice before (%.0f W against %.0f W): a choice, CP %.0f W kept",
                     mean_power, mean_target, followed_power, followed_target, cp)
            return None
        # An exhausted rider holds its CP: not below the power it holds.
        new_cp = max(self.balance.fit_critical_power(st.down_factor * cp, cp), mean_power)
        if new_cp > cp * (1 - st.min_change):  # the balance explains it, or too small to tell
            log.info("cp_monitor: rider holds %.0f W against %.0f W advised; the power "
                     "history explains it at CP %.0f W: CP %.0f W kept", mean_power,
                     mean_target, new_cp, cp)
            return None
        log.info("cp_monitor: rider holds %.0f W against %.0f W advised after following the "
                 "advice: CP %.0f -> %.0f W unless a surge in the next %.0f s says otherwise",
                 mean_power, mean_target, cp, new_cp, st.confirm_s)
        return Refit(stamp_s, state.s_m, "down", cp, new_cp, mean_power, mean_target,
                     float(recent[-1, 0] - recent[0, 0]), state.w_prime_j)

    def _confirm_down(self, stamp_s: float, state: RiderState) -> Refit | None:
        """Adopt the pending down-refit after `confirm_s` without a surge to CP (a mean
        over `surge_mean_s` of the power since it was found), or cancel it at one."""
        st, pending = self.settings, self._pending
        assert pending is not None
        rows = np.array([r for r in self._rows if r[0] > pending.stamp_s])
        if len(rows):
            # The mean over the last `surge_mean_s` at each row, once that much has passed.
            ends = rows[:, 0] >= rows[0, 0] + st.surge_mean_s - 1.0
            means = [rows[(rows[:, 0] > t - st.surge_mean_s) & (rows[:, 0] <= t), 2].mean()
                     for t in rows[ends, 0]]
            if means and max(means) >= self.cp_in_use_w:
                self._pending = None
                self.down_cancelled += 1
                self._rows.clear()  # the next down-refit needs evidence of its own
                log.info("cp_monitor: CP %.0f -> %.0f W cancelled: the rider surged to %.0f W "
                         "over %.0f s after %.0f W held: not out of W'", pending.cp_before_w,
                         pending.cp_after_w, max(means), st.surge_mean_s, pending.power_held_w)
                return None
        if stamp_s - pending.stamp_s < st.confirm_s:
            return None
        return self._adopt(dataclasses.replace(pending, stamp_s=stamp_s, s_m=state.s_m))

    def _adopt(self, refit: Refit) -> Refit:
        self._pending = None  # an up-refit supersedes a pending down one
        self.balance.use_critical_power(refit.cp_after_w)
        self.refits.append(refit)
        self._rows.clear()
        log.warning("engine: %s", refit.message())
        return refit

    def counts(self) -> dict[str, int]:
        """The engine's counters of what was not refitted: `cp_up_held` (the balance below
        zero with no higher CP proven) and `cp_down_cancelled` (a surge before the
        confirmation)."""
        return {"cp_up_held": self.up_held, "cp_down_cancelled": self.down_cancelled}

    def diagnostic(self, stamp_s: float) -> Diagnostic:
        """`itt_planner/rider_model`: the CP in use, the refits so far and the last one's
        evidence (WARN once there was a refit, or while `holding`)."""
        values = {"cp_believed_w": f"{self.rider.critical_power_w:.1f}",
                  "cp_in_use_w": f"{self.cp_in_use_w:.1f}", "refits": str(len(self.refits)),
                  "refits_up": str(sum(r.direction == "up" for r in self.refits)),
                  "refits_down": str(sum(r.direction == "down" for r in self.refits)),
                  "up_held": str(self.up_held), "down_cancelled": str(self.down_cancelled)}
        if self.holding:
            return Diagnostic(stamp_s, "itt_planner/rider_model", Level.WARN,
                              f"W' shown as 0: the balance at CP {self.cp_in_use_w:.0f} W is "
                              "below zero, but the power held proves no higher CP", values)
        if not self.refits:
            return Diagnostic(stamp_s, "itt_planner/rider_model", Level.OK,
                              "CP as believed: no refit", values)
        last = self.refits[-1]
        values.update({f"last_{k}": v for k, v in last.values().items()})
        return Diagnostic(stamp_s, "itt_planner/rider_model", Level.WARN, last.message(), values)
