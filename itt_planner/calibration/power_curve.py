"""CP and W' from the mean-maximal power (MMP) curve: 2- and 3-parameter models.

The MMP curve is the best average power a rider held for each duration in the rides
(moving samples only, pauses cut). Two critical-power models are fitted to it by
nonlinear least squares (`scipy.optimize.curve_fit`, uncertainties from the covariance):

- 2-parameter (Monod & Scherrer): P(t) = CP + W' / t, on 2-20 min efforts, where it
  holds (shorter efforts are limited by peak power, longer by fatigue beyond W');
- 3-parameter (Morton): P(t) = CP + W' / (t + W' / (P_max - CP)), on 10 s - 20 min,
  which bends the curve to a finite peak power.

Both are fitted to the curve's upper ENVELOPE: an MMP point is often a piece of a longer
effort (the best 150 s inside a 180 s effort) and lies below the rider's curve, so after
a first fit the points more than 3 % below it are dropped and the model refitted, until
the set is stable (at least 4 points kept); a real curve bends a little off either
model (at 1 % every effort over 8 min of a hard 80 min ride was dropped). The durations
used are reported.

The rider's CP and W' are the 2-parameter model's (the planner's W' balance, E9, is
built on it); the 3-parameter figures are reported beside them. A ride whose efforts
were not maximal gives a curve below the rider's capacity, so CP and W' are lower
bounds; several rides (the best of each duration) tighten them. Refused: fewer than
4 durations of the range in the rides (too short), or a fit without a positive CP and W'.

A W' outside what riders have (`W_PRIME_PLAUSIBLE_J`) is kept but warned about
(`submaximal_warning`): an evenly paced time trial or a steady ride has a flat curve from
2 to 20 min, so the fit puts CP near the steady power and W' near nothing (the Zwift
Bologna TT: CP 292 W, W' 2.6 kJ; MMP(2 min) 8 % over MMP(20 min) where a rider's
maximal efforts give 20-50 %).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import curve_fit

from itt_planner.calibration.ride_data import CalibrationError, PowerSeries, RideSeries
from itt_planner.model.mean_max import mean_max_power

#: Durations (s) of the MMP curve.
DURATIONS_S = (1, 5, 10, 15, 20, 30, 45, 60, 90, 120, 150, 180, 240, 300, 360, 420, 480, 600,
               720, 900, 1200, 1500, 1800, 2400, 3600)
#: Range of each model (s).
RANGE_2P_S = (120.0, 1200.0)
RANGE_3P_S = (10.0, 1200.0)
#: An MMP point further than this below a fit is a piece of a longer effort (see doc).
_ENVELOPE_TOL = 0.03
#: W' (J) trained cyclists' maximal tests give (about 6-40 kJ in the CP literature:
#: Jones et al. 2010, Skiba et al. 2012); outside it the curve's efforts were not maximal.
W_PRIME_PLAUSIBLE_J = (6_000.0, 40_000.0)


@dataclass(frozen=True)
class CpFit:
    """One critical-power model fitted to the MMP curve.

    Attributes:
        durations_s: the durations used.
        rmse_w, r2: fit quality on those durations.
        p_max_w: the 3-parameter model's peak power (NaN for the 2-parameter one).
    """

    model: str
    cp_w: float
    cp_std_w: float
    w_prime_j: float
    w_prime_std_j: float
    p_max_w: float
    durations_s: tuple[int, ...]
    rmse_w: float
    r2: float

    def predict(self, t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, float)
        if self.model == "2p":
            return self.cp_w + self.w_prime_j / t
        return _morton(t, self.cp_w, self.w_prime_j, self.p_max_w)

    def as_dict(self) -> dict[str, object]:
        out: dict[str, object] = {
            "cp_w": round(self.cp_w, 1), "cp_std_w": round(self.cp_std_w, 1),
            "w_prime_j": round(self.w_prime_j), "w_prime_std_j": round(self.w_prime_std_j),
            "durations_s": list(self.durations_s), "rmse_w": round(self.rmse_w, 1),
            "r2": round(self.r2, 4)}
        if math.isfinite(self.p_max_w):
            out["p_max_w"] = round(self.p_max_w, 1)
        return out


def mmp_curve(rides: Sequence[RideSeries | PowerSeries], durations_s: tuple[int, ...] = DURATIONS_S
              ) -> dict[int, float]:
    """Best average power per duration over all rides, on 1 Hz moving time.

    Each continuous stretch is resampled to 1 s; windows never span a pause. Durations
    longer than every stretch are left out.
    """
    best: dict[int, float] = {}
    for ride in rides:
        for b in np.unique(ride.block):
            idx = np.flatnonzero(ride.block == b)
            if len(idx) < 2:
                continue
            t = ride.t_s[idx]
            grid = np.arange(t[0], t[-1] + 1e-9, 1.0)
            # Power as recorded is held until the next record (the meter's average).
            p = ride.power_w[idx][np.searchsorted(t, grid, side="right") - 1]
            energy = np.concatenate([[0.0], np.cumsum(p)])
            for d, value in mean_max_power(energy, durations_s).items():
                best[d] = max(best.get(d, 0.0), value)
    return best


def _morton(t: np.ndarray, cp: float, w_prime: float, p_max: float) -> np.ndarray:
    return cp + w_prime / (t + w_prime / (p_max - cp))


def fit_cp(mmp: dict[int, float], model: str = "2p") -> CpFit:
    """Fit the 2- or 3-parameter model to the MMP points in its duration range.

    Raises:
        CalibrationError: fewer than 4 durations in range (rides too short for the
            model), or a fit that does not give CP > 0, W' > 0 (and P_max > CP).
    """
    lo, hi = RANGE_2P_S if model == "2p" else RANGE_3P_S
    durations = tuple(d for d in sorted(mmp) if lo <= d <= hi)
    if len(durations) < 4:
        longest = max(mmp) if mmp else 0
        raise CalibrationError(
            f"too short for the {model} critical-power model: efforts of {lo:.0f}-{hi:.0f} s "
            f"needed at >= 4 durations, the rides have {len(durations)} (longest {longest} s)")
    kept = durations
    for _ in range(6):
        fit = _fit(mmp, kept, model)
        t_all = np.array(durations, float)
        p_all = np.array([mmp[d] for d in durations])
        rel = p_all / fit.predict(t_all) - 1.0
        above = tuple(d for d, r in zip(durations, rel, strict=True) if r >= -_ENVELOPE_TOL)
        if len(above) < 4:
            order = np.argsort(-rel)[:4]
            above = tuple(sorted(durations[i] for i in order))
        if above == kept:
            break
        kept = above
    return fit


def submaximal_warning(fit: CpFit, mmp: dict[int, float]) -> str | None:
    """Why `fit`'s CP and W' are not the rider's, when its W' is outside
    `W_PRIME_PLAUSIBLE_J`; None when it is inside."""
    lo, hi = W_PRIME_PLAUSIBLE_J
    if lo <= fit.w_prime_j <= hi:
        return None
    first, last = fit.durations_s[0], fit.durations_s[-1]
    rise = mmp[first] / mmp[last] - 1.0
    if fit.w_prime_j < lo:
        why = ("the rides hold no maximal effort shorter than their steady ones, so W' is a "
               "lower bound and CP may be above the rider's (set by the steady power)")
    else:
        why = "the short efforts were maximal and the long ones not, so CP is a lower bound"
    return (f"W' {fit.w_prime_j / 1000:.1f} kJ is outside the {lo / 1000:.0f}-{hi / 1000:.0f} "
            f"kJ of riders' maximal tests (best {first} s power {100 * rise:.0f} % above the "
            f"best {last} s): {why}; calibrate CP and W' on rides with all-out efforts of "
            f"2-5 and 10-20 min")


def _fit(mmp: dict[int, float], durations: tuple[int, ...], model: str) -> CpFit:
    """One least-squares fit of `model` on exactly `durations`."""
    t = np.array(durations, float)
    p = np.array([mmp[d] for d in durations])
    try:
        if model == "2p":
            popt, pcov = curve_fit(lambda x, cp, w: cp + w / x, t, p,
                                   p0=(p[-1] * 0.9, 20_000.0))
            p_max, p_max_ok = math.nan, True
        else:
            popt, pcov = curve_fit(_morton, t, p, p0=(p[-1] * 0.9, 20_000.0, max(mmp.values())),
                                   bounds=([1.0, 100.0, p[-1]], [p[-1] * 1.5, 2e5, 4000.0]))
            p_max = float(popt[2])
            p_max_ok = p_max > popt[0]
    except (RuntimeError, ValueError) as err:
        raise CalibrationError(f"{model} critical-power fit failed: {err}") from None
    cp, w_prime = float(popt[0]), float(popt[1])
    if cp <= 0 or w_prime <= 0 or not p_max_ok:
        raise CalibrationError(f"{model} critical-power fit is not physical: CP {cp:.0f} W, "
                               f"W' {w_prime:.0f} J (the efforts are not maximal?)")
    std = np.sqrt(np.maximum(np.diag(pcov), 0.0))
    fit = CpFit(model, cp, float(std[0]), w_prime, float(std[1]), p_max, durations, 0.0, 0.0)
    resid = p - fit.predict(t)
    total = float(np.sum((p - p.mean()) ** 2))
    return CpFit(model, cp, float(std[0]), w_prime, float(std[1]), p_max, durations,
                 float(np.sqrt(np.mean(resid ** 2))),
                 1.0 - float(np.sum(resid ** 2)) / total if total > 0 else math.nan)
