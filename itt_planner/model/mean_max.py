"""Mean-maximal power: the best average power held over each duration of a power
history, the curve the critical-power model (P(T) = CP + W'/T) is read against.

One definition for both its users: calibration's MMP curve of a ride
(`calibration.power_curve.mmp_curve`, the CP and W' fit) and the live CP monitor's
proof of a CP the rider has shown (`live.wprime_balance.WPrimeBalance.proven_critical_power`).
They differ only in how a history becomes energy on a 1 s grid (a ride's 1 Hz samples;
the engine's readings each held up to its `power_hold_s`).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np


def mean_max_power(energy_j: np.ndarray, durations_s: Iterable[float]) -> dict[int, float]:
    """The best mean power (W) over each duration (s, whole seconds) of the cumulative
    energy `energy_j` (J at 0, 1, 2, ... s). Durations the history does not span are
    left out."""
    e = np.asarray(energy_j, float)
    best: dict[int, float] = {}
    for d in durations_s:
        k = int(d)
        if 0 < k < len(e):
            best[k] = float(np.max(e[k:] - e[:-k])) / k
    return best
