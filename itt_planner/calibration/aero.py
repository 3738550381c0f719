"""CdA and crr from power, speed and altitude: the virtual-elevation fit (Chung's method).

Over one interval of a ride, the work at the wheel goes into kinetic energy, height,
rolling resistance and air drag (model.md E3, still air, no braking):

    eta P dt = d(m v^2 / 2) + m g dh + crr m g v dt + (rho CdA / 2) v^3 dt

so the height the power "explains" (the virtual elevation) is

    dh_ve = (eta P dt - d(m v^2 / 2)) / (m g) - crr v dt
            - CdA rho (v - u)|v - u| v dt / (2 m g),   u = w_E cos(psi) + w_N sin(psi)

(`u`: the wind along the GPS heading `psi`, one steady wind per ride, as E3 projects
it). Summed from the start of a stretch and compared with the recorded altitude plus a
free offset per stretch, it is fitted by nonlinear least squares
(`scipy.optimize.least_squares`) for (crr, CdA, wind) with the mass given, or
(mass, CdA, wind) with crr at its prior when the mass is not given (mass and crr are
nearly collinear: climbs pin the mass, but not both). Kinetic energy telescopes, so speed
noise enters only at the stretch ends. Only intervals where the balance holds are used: pedalling (a
rider who coasts may be braking, which a power meter cannot see), above walking speed,
no hard acceleration or braking, no tight cornering (GPS yaw rate), and not next to a
gap. The uncertainty is a bootstrap over stretches (the errors within one stretch are
correlated: wind, altimeter drift). crr is weakly identified without speed variety; a
crr outside a plausible band is fixed to its prior and said so; a mass at the edge of
its range is a refusal (pass it). A CdA no physical rider has is a refusal: the speed
cannot come from that power (a virtual ride's simulated speed, a wrong mass, a broken meter;
too much drag that a free crr explains as a rolling resistance no road has: an unpaved
ride, and the refusal says so).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from itt_planner.calibration.aero_design import Design, Selection, design
from itt_planner.calibration.ride_data import CalibrationError, RideSeries
from itt_planner.units import MPS_TO_KMH

#: CdA outside this band is no rider on a bicycle (m^2): refused, not reported.
PHYSICAL_CDA_M2 = (0.15, 0.60)
#: Bounds of the fit: wind components (m/s), crr.
_WIND_MAX_MPS = 12.0
_CRR_BOUNDS = (-0.05, 0.08)


@dataclass(frozen=True)
class AeroSettings:
    """What the fit assumes and how hard it looks.

    Attributes:
        mass_kg: rider + bicycle; None: estimated (crr then at `crr_prior`).
        drivetrain_efficiency: wheel power / measured power (1.0: the meter's power
            reaches the road).
        selection: which intervals hold the balance (`aero_design.Selection`).
        crr_prior: crr used when it is not fitted.
        crr_band: a fitted crr outside this band is not believed (fixed to the prior).
        fit_wind: fit one steady wind per ride (False: still air).
        bootstrap: resamples of the stretches for the standard deviations.
        mass_range_kg: the estimated mass must lie inside (not at the edge).
        simulated_rmse_m: a virtual elevation this close to the recorded one (m RMS)
            is no real road: barometers quantise by ~0.2 m and drift, gusts vary.
        allow_simulated: fit such a ride anyway.
        setup_of_ride: per ride, the index of its setup (position or bike): one CdA is
            fitted per setup, crr, mass and wind shared as before; empty: one setup.
    """

    mass_kg: float | None = None
    drivetrain_efficiency: float = 1.0
    selection: Selection = Selection()
    crr_prior: float = 0.004
    crr_band: tuple[float, float] = (0.002, 0.012)
    fit_wind: bool = True
    bootstrap: int = 100
    seed: int = 0
    mass_range_kg: tuple[float, float] = (45.0, 150.0)
    simulated_rmse_m: float = 0.3
    allow_simulated: bool = False
    setup_of_ride: tuple[int, ...] = ()


@dataclass(frozen=True, eq=False)
class AeroFit:
    """The fitted drag area, rolling resistance, mass and wind, with bootstrap sds.

    Attributes:
        crr_fixed: crr was not fitted but set to the prior (`crr_note` says why).
        wind_mps: per ride, the fitted wind (east, north) the air moves TO (m/s).
        used_s: time of the intervals that entered the fit.
        rmse_m: RMS of virtual minus recorded elevation (after the stretch offsets).
        stretches: (start, end) sample indices of the FIRST ride's stretches (figure).
        virtual_ele_m: the first ride's virtual elevation on those samples (NaN
            elsewhere), shifted to the recorded one per stretch.
        setup_cda_m2, setup_cda_std_m2: CdA and its sd per setup (`cda_m2` is the
            first ride's setup's).
    """

    cda_m2: float
    cda_std_m2: float
    mass_kg: float
    mass_std_kg: float
    mass_estimated: bool
    crr: float
    crr_std: float
    crr_fixed: bool
    crr_note: str
    wind_mps: np.ndarray
    wind_std_mps: np.ndarray
    used_s: float
    n_stretches: int
    rmse_m: float
    air_density_kgpm3: float
    stretches: list[tuple[int, int]] = field(default_factory=list)
    virtual_ele_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    setup_cda_m2: tuple[float, ...] = ()
    setup_cda_std_m2: tuple[float, ...] = ()

    def as_dict(self) -> dict[str, object]:
        winds = [wind_meteo(w) for w in self.wind_mps]
        return {"cda_m2": round(self.cda_m2, 4), "cda_std_m2": round(self.cda_std_m2, 4),
                "mass_kg": round(self.mass_kg, 1), "mass_std_kg": round(self.mass_std_kg, 1),
                "mass_estimated": self.mass_estimated,
                "crr": round(self.crr, 5), "crr_std": round(self.crr_std, 5),
                "crr_fixed": self.crr_fixed, "crr_note": self.crr_note,
                "wind": [{"speed_kmh": round(k, 1), "from_deg": round(d, 0),
                          "std_kmh": round(MPS_TO_KMH * float(np.hypot(*sd)), 1)}
                         for (k, d), sd in zip(winds, self.wind_std_mps, strict=True)],
                "used_s": round(self.used_s, 1), "n_stretches": self.n_stretches,
                "virtual_elevation_rmse_m": round(self.rmse_m, 2),
                "air_density_kgpm3": round(self.air_density_kgpm3, 4),
                "setup_cda_m2": [round(c, 4) for c in self.setup_cda_m2],
                "setup_cda_std_m2": [round(c, 4) for c in self.setup_cda_std_m2]}


def wind_meteo(wind_enu_mps: np.ndarray) -> tuple[float, float]:
    """(speed km/h, direction FROM in degrees clockwise from North) of an ENU wind
    (where the air moves TO): the units of `Conditions.from_meteo`."""
    e, n = float(wind_enu_mps[0]), float(wind_enu_mps[1])
    return MPS_TO_KMH * math.hypot(e, n), math.degrees(math.atan2(-e, -n)) % 360.0


class _Problem:
    """The parameters one fit frees (mass, crr, one cda per setup, wind per ride) around
    fixed values."""

    def __init__(self, des: Design, free: tuple[str, ...], fixed: dict[str, float],
                 fit_wind: bool, mass_range: tuple[float, float],
                 setup_of_ride: tuple[int, ...] = ()) -> None:
        self.des, self.free, self.fixed, self.fit_wind = des, free, fixed, fit_wind
        setups = np.asarray(setup_of_ride or (0,) * des.n_rides, int)
        self.n_setups = int(setups.max()) + 1
        self.setup_of_interval = setups[des.ride_of]
        self.sizes = {k: (self.n_setups if k == "cda" else 1) for k in free}
        lo = {"mass": mass_range[0], "crr": _CRR_BOUNDS[0], "cda": 0.01}
        hi = {"mass": mass_range[1], "crr": _CRR_BOUNDS[1], "cda": 2.0}
        nw = 2 * des.n_rides if fit_wind else 0
        self.n_free = sum(self.sizes.values())
        self.lower = np.array([lo[k] for k in free for _ in range(self.sizes[k])]
                              + [-_WIND_MAX_MPS] * nw)
        self.upper = np.array([hi[k] for k in free for _ in range(self.sizes[k])]
                              + [_WIND_MAX_MPS] * nw)

    def unpack(self, x: np.ndarray) -> tuple[float, float, np.ndarray, np.ndarray]:
        """(mass, crr, CdA per setup, wind per ride)."""
        values: dict[str, Any] = dict(self.fixed)
        i = 0
        for k in self.free:
            values[k] = x[i] if self.sizes[k] == 1 else x[i:i + self.sizes[k]]
            i += self.sizes[k]
        cda = np.broadcast_to(np.asarray(values["cda"], float), (self.n_setups,))
        wind = (x[self.n_free:].reshape(-1, 2) if self.fit_wind
                else np.zeros((self.des.n_rides, 2)))
        return float(values["mass"]), float(values["crr"]), cda, wind

    def residual(self, x: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        mass, crr, cda, wind = self.unpack(x)
        return self.des.residual(mass, crr, cda[self.setup_of_interval], wind, weights=weights)

    def solve(self, x0: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        x0 = np.clip(x0, self.lower + 1e-9, self.upper - 1e-9)
        def residual(x: np.ndarray) -> np.ndarray:
            return self.residual(x, weights)

        res = least_squares(residual, x0, bounds=(self.lower, self.upper), x_scale="jac")
        return np.asarray(res.x)

    def start(self, mass: float, crr: float) -> np.ndarray:
        guess = {"mass": mass, "crr": crr, "cda": 0.3}
        nw = 2 * self.des.n_rides if self.fit_wind else 0
        return np.array([guess[k] for k in self.free for _ in range(self.sizes[k])]
                        + [0.0] * nw)

    def rmse(self, x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(self.residual(x) ** 2)))


def fit_aero(rides: list[RideSeries], st: AeroSettings) -> AeroFit:
    """CdA, crr (or mass) and the wind of one rider from one or more rides.

    Raises:
        CalibrationError: fewer than 3 usable stretches (too much coasting, stopping or
            cornering); a mass at the edge of its range (not identified: pass it); a CdA
            no physical rider has (names the value and the likely cause); or a balance
            that holds too exactly for a real road (a virtual ride's simulated speed),
            unless `st.allow_simulated`.
    """
    names = ", ".join(r.source for r in rides)
    des = design(rides, st.selection, st.drivetrain_efficiency)
    if len(des.spans) < 3:
        raise CalibrationError(
            f"{names}: only {len(des.spans)} stretches of >= {st.selection.min_stretch_s:.0f} s "
            "where the power balance holds (pedalling, moving, no braking or hard cornering); "
            "need at least 3")
    mass0 = st.mass_kg if st.mass_kg is not None else 80.0
    setups = st.setup_of_ride
    if st.mass_kg is None:
        prob = _Problem(des, ("mass", "cda"), {"crr": st.crr_prior}, st.fit_wind,
                        st.mass_range_kg, setups)
        note = f"mass estimated with crr at the prior {st.crr_prior} (mass and crr are collinear)"
    else:
        prob = _Problem(des, ("crr", "cda"), {"mass": st.mass_kg}, st.fit_wind,
                        st.mass_range_kg, setups)
        note = "fitted"
    x = prob.solve(prob.start(mass0, st.crr_prior))
    mass, crr, cda, wind = prob.unpack(x)
    if st.mass_kg is None and min(mass - st.mass_range_kg[0], st.mass_range_kg[1] - mass) < 1.0:
        raise CalibrationError(f"{names}: the mass is not identified by the ride (the best fit "
                               f"is at the edge of {st.mass_range_kg} kg); pass --mass-kg")
    # The closest ANY crr and CdA get at this mass: the test of a too-perfect balance.
    free = _Problem(des, ("crr", "cda"), {"mass": mass}, st.fit_wind, st.mass_range_kg, setups)
    x_free = free.solve(free.start(mass, crr))
    rmse_free = free.rmse(x_free)
    if st.mass_kg is not None and not st.crr_band[0] <= crr <= st.crr_band[1]:
        note = (f"fitted crr {crr:.4f} is outside {list(st.crr_band)}: the ride cannot separate "
                f"rolling from air drag; crr fixed to {st.crr_prior}")
        prob = _Problem(des, ("cda",), {"mass": st.mass_kg, "crr": st.crr_prior}, st.fit_wind,
                        st.mass_range_kg, setups)
        x = prob.solve(prob.start(mass0, st.crr_prior))
        mass, crr, cda, wind = prob.unpack(x)
    for value in cda:
        if not PHYSICAL_CDA_M2[0] <= value <= PHYSICAL_CDA_M2[1]:
            why = (f"{names}: speed and power disagree with any physical rider: the best power "
                   f"balance needs CdA {value:.3f} m^2 (crr {crr:.4f}, mass {mass:.0f} kg), "
                   f"outside {PHYSICAL_CDA_M2[0]}-{PHYSICAL_CDA_M2[1]} m^2")
            raise CalibrationError(why + (_rolling_cause(des, st, setups, mass0)
                                          if value > PHYSICAL_CDA_M2[1] else _OTHER_CAUSES))
    if rmse_free < st.simulated_rmse_m and not st.allow_simulated:
        raise CalibrationError(
            f"{names}: the speed is simulated, not measured (or the power is): power, speed and "
            f"altitude obey one power balance to {rmse_free:.2f} m RMS of virtual elevation over "
            f"{len(des.spans)} stretches (CdA {cda[0]:.3f} m^2, mass {mass:.0f} kg), tighter "
            f"than any real altimeter and wind allow (>= {st.simulated_rmse_m} m). This is a "
            "virtual ride (Zwift and similar: its speed is the game's physics, not the "
            "rider's; --allow-virtual fits the game's rider anyway), or an app's power "
            "estimated from speed and altitude, with no power meter (a phone app's 'power')")
    boot = [prob.unpack(b) for b in _bootstrap(prob, x, len(des.spans), st)]
    mass_sd, crr_sd = (float(np.std(np.array([float(b[i]) for b in boot]), ddof=1))
                       for i in (0, 1))
    cda_sd = np.std(np.array([b[2] for b in boot]), axis=0, ddof=1)
    wind_sd = np.std(np.array([b[3] for b in boot]), axis=0, ddof=1)
    first = [(lo, hi) for k, lo, hi in des.spans if k == 0]
    own = setups[0] if setups else 0  # the first ride's setup: the rider's CdA
    return AeroFit(
        cda_m2=float(cda[own]), cda_std_m2=float(cda_sd[own]), mass_kg=mass,
        mass_std_kg=mass_sd, mass_estimated=st.mass_kg is None, crr=crr, crr_std=crr_sd,
        crr_fixed=note != "fitted", crr_note=note, wind_mps=wind, wind_std_mps=wind_sd,
        used_s=float(sum(rides[k].t_s[hi] - rides[k].t_s[lo] for k, lo, hi in des.spans)),
        n_stretches=len(des.spans), rmse_m=prob.rmse(x),
        air_density_kgpm3=float(np.mean(np.concatenate([r.rho_kgpm3 for r in rides]))),
        stretches=first,
        virtual_ele_m=_virtual_elevation(rides[0], des, mass, crr,
                                         cda[prob.setup_of_interval], wind),
        setup_cda_m2=tuple(float(c) for c in cda),
        setup_cda_std_m2=tuple(float(c) for c in cda_sd))


#: Why a CdA no rider has, when rolling resistance does not explain it.
_OTHER_CAUSES = (". The speed is probably simulated (a virtual ride), or the mass or the "
                 "power meter is wrong")


def _rolling_cause(des: Design, st: AeroSettings, setups: tuple[int, ...], mass_kg: float
                   ) -> str:
    """Why a ride needs more drag than any rider has: with crr free at `mass_kg`, a
    rolling resistance no road tyre on tarmac has and a rider's CdA (an unpaved ride: a
    mountain-bike race lap's best balance with crr at 0.004 needs CdA 0.63; at 80 kg
    with crr free, crr 0.018 and CdA 0.39); else `_OTHER_CAUSES`."""
    free = _Problem(des, ("crr", "cda"), {"mass": mass_kg}, st.fit_wind, st.mass_range_kg,
                    setups)
    _, crr, cda, _ = free.unpack(free.solve(free.start(mass_kg, st.crr_prior)))
    low, high = PHYSICAL_CDA_M2
    if crr <= st.crr_band[1] or not all(low <= value <= high for value in cda):
        return _OTHER_CAUSES
    return (f". With crr free at {mass_kg:.0f} kg it needs crr {crr:.3f} and CdA "
            f"{', '.join(f'{value:.3f}' for value in cda)} m^2: a rolling resistance no road "
            f"tyre on tarmac has ({st.crr_band[0]}-{st.crr_band[1]}): an unpaved surface "
            "(gravel, dirt, a mountain-bike trail), soft or knobbly tyres, a rubbing brake; "
            "or the mass (--mass-kg) or the power meter is wrong. The planner's rider rides "
            "a road: calibrate CdA on road rides")


def fit_day_wind(ride: RideSeries, mass_kg: float, crr: float, cda_m2: float,
                 efficiency: float = 1.0, selection: Selection = Selection()) -> np.ndarray:
    """The steady wind (east, north, m/s, where the air moves TO) that best explains one
    ride for a known rider: the conditions of the day, for validating that rider.

    Raises:
        CalibrationError: fewer than 3 usable stretches.
    """
    des = design([ride], selection, efficiency)
    if len(des.spans) < 3:
        raise CalibrationError(f"{ride.source}: only {len(des.spans)} stretches where the power "
                               "balance holds; the wind of the day cannot be fitted")
    prob = _Problem(des, (), {"mass": mass_kg, "crr": crr, "cda": cda_m2}, True, (1.0, 1e3))
    wind: np.ndarray = prob.unpack(prob.solve(prob.start(mass_kg, crr)))[3][0]
    return wind


def _bootstrap(prob: _Problem, x: np.ndarray, n_stretches: int, st: AeroSettings
               ) -> list[np.ndarray]:
    """Refits on stretches resampled with replacement (multiplicities as weights): the
    errors within one stretch (gusts, altimeter drift) are correlated, across stretches
    much less."""
    rng = np.random.default_rng(st.seed)
    out = []
    for _ in range(st.bootstrap):
        counts = np.bincount(rng.integers(0, n_stretches, n_stretches),
                             minlength=n_stretches).astype(float)
        out.append(prob.solve(x, weights=counts))
    return out


def _virtual_elevation(ride: RideSeries, des: Design, mass: float, crr: float,
                       cda: np.ndarray, wind: np.ndarray) -> np.ndarray:
    """The first ride's virtual elevation on its samples (NaN off-stretch), each stretch
    shifted to the recorded altitude's mean (the fit's free offset)."""
    height = des.virtual_height(mass, crr, cda, wind)
    ve = np.full(len(ride), np.nan)
    for g, (k, lo, hi) in enumerate(des.spans):
        if k != 0:
            continue
        virt = height[des.group == g]
        ve[lo:hi + 1] = virt + np.mean(ride.ele_m[lo:hi + 1] - virt)
    return ve
