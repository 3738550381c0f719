"""W' balance (model.md E9): the rate of change of normalised anaerobic capacity.

Written with operations NumPy floats and CasADi symbols share, so the OCP (symbolic) and
the estimator (numeric) use one definition. Rates are per second; the spatial form of
E9 divides by `s_dot`. `e_n_along`: the balance over a sequence of held powers, for the
live estimator and the horizon's W' targets (one loop for both).
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import Enum
from typing import Any

import casadi as ca
import numpy as np

#: Width of the band below full W' over which the paper variant's recovery fades out.
_PAPER_CAP_BAND = 0.02


class WPrimeModel(str, Enum):  # noqa: UP042  (StrEnum would change str(); a refactor keeps it)
    """Which E9 variant: the Skiba differential model (default) or the paper's."""

    SKIBA = "skiba"
    PAPER = "paper"


def e_n_rate(e_n: Any, p_plus_w: Any, critical_power_w: Any, w_prime_j: Any,
             model: WPrimeModel = WPrimeModel.SKIBA, *, sharpness_w: float = 0.0) -> Any:
    """d E_n / dt for normalised W' `e_n` and pedalling power `p_plus_w` >= 0 (E9).

    Skiba: depletion `-(P+ - W_C)/E_0` above `W_C`, recovery `(W_C - P+)(1 - E_n)/E_0`
    below. Paper [fix]: the symmetric model, whose recovery fades out over the last
    `_PAPER_CAP_BAND` below full, so W' never grows above 1 yet riding below CP stays
    allowed (a hard cap would be a non-smooth constraint the NLP cannot handle).
    `sharpness_w` > 0 smooths the switch at `W_C` (a softplus of that width in watts)
    for a gradient-based solver; 0 gives the exact kink. Numbers (the estimator) or
    CasADi symbols (the OCP, with the rider's parameters symbolic) alike.
    """
    excess = p_plus_w - critical_power_w
    if sharpness_w > 0:
        above = sharpness_w * ca.log1p(ca.exp(excess / sharpness_w))
    else:
        above = ca.fmax(excess, 0)
    below = above - excess  # = max(W_C - P+, 0), smoothed alike
    if model is WPrimeModel.SKIBA:
        recovery = below * (1 - e_n)
    else:
        recovery = below * ca.fmin(1, (1 - e_n) / _PAPER_CAP_BAND)
    return (recovery - above) / w_prime_j


def e_n_along(e0: float, power_w: Sequence[float], dt_s: Sequence[float],
              critical_power_w: float, w_prime_j: float,
              model: WPrimeModel = WPrimeModel.SKIBA, *, floor: float | None = None
              ) -> np.ndarray:
    """E_n from `e0` and after each step: pedalling power `power_w[k]` (>= 0) held for
    `dt_s[k]` (E9, one Euler step each: keep the steps short, ~1 s, over which W'
    changes by < 1 %). Capped at 1 (full); at `floor` from below if given, else free to
    run below zero (how the estimator sees a CP set too high)."""
    x = float(e0)
    out = [x]
    low = -np.inf if floor is None else floor
    # Written out on floats, each step clipped only on the side it moves to (the same
    # as clipping to [floor, 1] from a start within it): the estimator runs this over
    # the whole ride ~25 times per CP fit.
    for p, h in zip(power_w, dt_s, strict=True):
        if p > critical_power_w:
            x = max(x - (p - critical_power_w) / w_prime_j * h, low)
        elif model is WPrimeModel.SKIBA:
            x = min(x + (critical_power_w - p) * (1 - x) / w_prime_j * h, 1.0)
        else:
            x = min(x + float(e_n_rate(x, p, critical_power_w, w_prime_j, model)) * h, 1.0)
        out.append(x)
    return np.array(out)
