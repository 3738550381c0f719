"""The W' balance: measured power integrated against the critical power in use (E9).

`WPrimeBalance` is the engine's W' model and the one holder of the CP in use: the
balance is integrated with `wprime.e_n_along` (model.md E9, Skiba by default), each power
reading held until the next one for at most `power_hold_s`. The power history since the
start (or a restore) is kept, so that the balance can be replayed with another CP: that
is how a CP refit is found (`fit_critical_power`, asked by `cp_monitor.CpMonitor`) and
carried out (`use_critical_power`). The published balance (`state`) is never below 0:
a balance that would go below is the belief being wrong, which a refit corrects.

Not thread-safe: the engine calls it with its lock held. Readings arrive validated (the
estimator's power hook drops bad ones).
"""

from __future__ import annotations

import math

import numpy as np

from itt_planner.model.mean_max import mean_max_power
from itt_planner.model.rider import Rider
from itt_planner.model.wprime import WPrimeModel, e_n_along


class WPrimeBalance:
    """The W' balance of a rider at the CP in use (module docstring).

    Args:
        rider: W' and the believed CP (the CP in use until a refit).
        power_hold_s: a reading holds at most this long; beyond it power counts as 0.
        model: E9 variant.
    """

    def __init__(self, rider: Rider, power_hold_s: float,
                 model: WPrimeModel = WPrimeModel.SKIBA) -> None:
        self.w_prime_j = rider.w_prime_j
        #: The critical power in use (W): the believed one until a refit revises it.
        self.cp_w = rider.critical_power_w
        self.power_hold_s = power_hold_s
        self.model = model
        self._e_n = 1.0
        self._power_t: float | None = None
        self._power_w = 0.0
        #: Accepted power readings (stamp, W) since the start or a restore, and W' then:
        #: what `fit_critical_power` replays.
        self._power_log: list[tuple[float, float]] = []
        self._e_n_log_start = 1.0

    def add(self, stamp_s: float, power_w: float) -> None:
        """Integrate W' up to this reading with the previous power held (E9)."""
        if self._power_t is not None:
            self._e_n = self._e_n_at(stamp_s)
        self._power_t = stamp_s
        self._power_w = power_w
        self._power_log.append((stamp_s, power_w))

    def power_now(self, t: float) -> float:
        """The power held at `t` (0 after `power_hold_s` without a reading)."""
        if self._power_t is None or t - self._power_t > self.power_hold_s:
            return 0.0
        return self._power_w

    def balance_j(self, t: float) -> float:
        """The balance at `t` as published: never below 0."""
        return max(self._e_n_at(t), 0.0) * self.w_prime_j

    def raw_j(self, t: float) -> float:
        """The balance at `t` as integrated, below zero when the rider has done more than
        the CP in use allows (`balance_j` shows it clipped at 0)."""
        return self._e_n_at(t) * self.w_prime_j

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
            return self.cp_w
        target = w_prime_j / self.w_prime_j
        lo, hi = low_w, high_w
        if self._history_balance(hi)[0] <= target:
            return hi
        if self._history_balance(lo)[0] >= target:
            return lo
        for _ in range(25):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self._history_balance(mid)[0] < target else (lo, mid)
        return hi

    def proven_critical_power(self, durations_s: tuple[float, ...]
                              ) -> tuple[float, float, float]:
        """The least CP the power history proves with W' as believed: the highest
        MMP(T) - W'/T (the 2-parameter model, P(T) = CP + W'/T, which over-predicts what
        a rider holds below ~2 min, so a short T only proves less) over the durations
        `durations_s` the history spans, with that T and MMP(T): (CP, T, MMP), or
        (0, 0, 0) when it spans none. Power is held as in the balance."""
        if len(self._power_log) < 2:
            return 0.0, 0.0, 0.0
        stamps = np.array([s for s, _ in self._power_log])
        powers = np.array([p for _, p in self._power_log])
        held = np.minimum(np.diff(stamps), self.power_hold_s)
        # Energy is piecewise linear: each reading's power for its hold, then nothing.
        energy = np.concatenate([[0.0], np.cumsum(powers[:-1] * held)])
        knots_t = np.column_stack([stamps[:-1], stamps[:-1] + held]).ravel()
        knots_e = np.column_stack([energy[:-1], energy[1:]]).ravel()
        grid = np.arange(stamps[0], stamps[-1] + 1e-9, 1.0)
        mmp = mean_max_power(np.interp(grid, knots_t, knots_e), durations_s)
        return max([(0.0, 0.0, 0.0)]
                   + [(p - self.w_prime_j / k, float(k), p) for k, p in mmp.items()])

    def use_critical_power(self, cp_w: float) -> None:
        """Carry on with critical power `cp_w`: the balance now is that of the whole
        power history replayed with it."""
        self.cp_w = cp_w
        if len(self._power_log) >= 2:
            self._e_n = self._history_balance(cp_w)[1]
            self._power_t, self._power_w = self._power_log[-1]

    def snapshot(self, t: float | None) -> float:
        """The balance (J) at `t` (the last reading's when None), for a node restart."""
        e_n = self._e_n_at(t) if t is not None else self._e_n
        return e_n * self.w_prime_j

    def restore(self, w_prime_j: float, stamp_s: float | None) -> None:
        """Resume with balance `w_prime_j` at `stamp_s` (a new power history starts)."""
        self._e_n = float(w_prime_j) / self.w_prime_j
        self._power_t = stamp_s
        self._power_w = 0.0
        self._power_log = []
        self._e_n_log_start = self._e_n

    def _history_balance(self, cp_w: float) -> tuple[float, float]:
        """(lowest, last) normalised W' over the power history with CP `cp_w`."""
        stamps = np.array([s for s, _ in self._power_log])
        powers = [p for _, p in self._power_log[:-1]]
        dt = np.minimum(np.diff(stamps), self.power_hold_s).tolist()
        e = e_n_along(self._e_n_log_start, powers, dt, cp_w, self.w_prime_j, self.model)
        return float(e.min()), float(e[-1])

    def _e_n_at(self, t: float) -> float:
        """Normalised W' at `t` >= the last reading, the last power held (E9, Euler
        steps of at most 1 s: the balance changes by < 1 % of W' per second)."""
        if self._power_t is None or t <= self._power_t:
            return self._e_n
        held = min(t - self._power_t, self.power_hold_s)
        powers: list[float] = []
        steps: list[float] = []
        for span, power in ((held, self._power_w), (t - self._power_t - held, 0.0)):
            n = math.ceil(span)
            powers += [power] * n
            steps += [span / max(n, 1)] * n
        return float(e_n_along(self._e_n, powers, steps, self.cp_w, self.w_prime_j,
                               self.model)[-1])
