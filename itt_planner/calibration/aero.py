"""CdA and crr from power, speed and altitude: the virtual-elevation fit (Chung's method).

Over one interval of a ride, the work at the wheel goes into kinetic energy, height,
rolling resistance and air drag (model.md E3, still air, no braking):

    eta P dt = d(m v^2 / 2) + m g dh + crr m g v dt + (rho CdA / 2) v^3 dt

so the height the power "explains" (the virtual elevation) is

    dh_ve = (eta P dt - d(m v^2 / 2)) / (m g) - crr v dt - CdA rho v^3 dt / (2 m g).

Summed from the start of a stretch and compared with the recorded altitude plus a free
offset per stretch, this is LINEAR in (crr, CdA): ordinary least squares after
subtracting each stretch's mean. Kinetic energy telescopes, so speed noise enters only
at the stretch ends. Only intervals where the balance holds are used: pedalling (a
rider who coasts may be braking, which a power meter cannot see), above walking speed,
no hard acceleration or braking, no tight cornering (GPS yaw rate), and not next to a
gap. The uncertainty is a bootstrap over stretches (the errors within one stretch are
correlated: wind, altimeter drift). crr is weakly identified without speed variety; a
crr outside a plausible band or with a bootstrap spread over 40 % is fixed to a prior
and said so. A CdA no physical rider has is a refusal: the speed cannot come from
that power (a virtual ride's simulated speed, a wrong mass, a broken meter).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pymap3d

from itt_planner.calibration.ride_data import CalibrationError, RideSeries
from itt_planner.conditions import GRAVITY_MPS2

#: CdA outside this band is no rider on a bicycle (m^2): refused, not reported.
PHYSICAL_CDA_M2 = (0.15, 0.60)


@dataclass(frozen=True)
class AeroSettings:
    """Which intervals the fit trusts, the priors, and the bootstrap.

    Attributes:
        mass_kg: rider + bicycle; None: estimated (see `fit_aero`).
        drivetrain_efficiency: wheel power / measured power (1.0: the meter's power
            reaches the road, as the planner's model assumes).
        min_power_w: intervals below this are coasting (braking unseen): excluded.
        min_speed_mps: below this speed noise dominates: excluded.
        max_accel_mps2: |dv/dt| above this is a sprint or braking: excluded.
        max_lateral_mps2: lateral acceleration (GPS yaw rate x speed) above this is a
            corner, usually with braking: excluded.
        guard_s: this much around every excluded interval is excluded too.
        min_stretch_s, max_stretch_s: stretches shorter are dropped, longer are split.
        crr_prior: crr used when the data cannot separate it from CdA.
        crr_band: a fitted crr outside this band is not believed.
        bootstrap: resamples of the stretches.
    """

    mass_kg: float | None = None
    drivetrain_efficiency: float = 1.0
    min_power_w: float = 40.0
    min_speed_mps: float = 3.0
    max_accel_mps2: float = 0.7
    max_lateral_mps2: float = 2.0
    guard_s: int = 3
    min_stretch_s: float = 30.0
    max_stretch_s: float = 240.0
    crr_prior: float = 0.004
    crr_band: tuple[float, float] = (0.002, 0.012)
    bootstrap: int = 300
    seed: int = 0
    mass_range_kg: tuple[float, float] = (50.0, 140.0)
    #: A virtual elevation this close to the recorded one (m RMS) is no real road:
    #: barometers quantise by ~0.2 m and drift, and the wind is never still.
    simulated_rmse_m: float = 0.3
    allow_simulated: bool = False


@dataclass(frozen=True, eq=False)
class AeroFit:
    """The fitted drag area and rolling resistance, with bootstrap standard deviations.

    Attributes:
        crr_fixed: crr was not fitted but set to the prior (`crr_note` says why).
        used_s: time of the intervals that entered the fit.
        rmse_m: RMS of virtual minus recorded elevation (after the stretch offsets).
        stretches: (start, end) sample indices of the FIRST ride's stretches (figure).
        virtual_ele_m: the first ride's virtual elevation over those samples (NaN
            elsewhere), aligned to the recorded one per stretch.
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
    used_s: float
    n_stretches: int
    rmse_m: float
    air_density_kgpm3: float
    stretches: list[tuple[int, int]] = field(default_factory=list)
    virtual_ele_m: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def as_dict(self) -> dict[str, object]:
        return {"cda_m2": round(self.cda_m2, 4), "cda_std_m2": round(self.cda_std_m2, 4),
                "mass_kg": round(self.mass_kg, 1), "mass_std_kg": round(self.mass_std_kg, 1),
                "mass_estimated": self.mass_estimated,
                "crr": round(self.crr, 5), "crr_std": round(self.crr_std, 5),
                "crr_fixed": self.crr_fixed, "crr_note": self.crr_note,
                "used_s": round(self.used_s, 1), "n_stretches": self.n_stretches,
                "virtual_elevation_rmse_m": round(self.rmse_m, 2),
                "air_density_kgpm3": round(self.air_density_kgpm3, 4)}


def lateral_accel_mps2(ride: RideSeries) -> np.ndarray:
    """|v x yaw rate| per sample from the GPS track's heading (NaN without positions)."""
    lat, lon = ride.lat_deg, ride.lon_deg
    good = np.isfinite(lat) & np.isfinite(lon)
    if good.sum() < 3:
        return np.full(len(ride), np.nan)
    i0 = int(np.flatnonzero(good)[0])
    x, y, _ = pymap3d.geodetic2enu(lat, lon, 0.0, lat[i0], lon[i0], 0.0)
    # Heading over +-2 samples: single 1 Hz fixes jitter by metres.
    k = 2
    dx = np.full(len(ride), np.nan)
    dy = np.full(len(ride), np.nan)
    dx[k:-k], dy[k:-k] = x[2 * k:] - x[:-2 * k], y[2 * k:] - y[:-2 * k]
    heading = np.unwrap(np.nan_to_num(np.arctan2(dy, dx)))
    yaw = np.gradient(heading, ride.t_s)
    out = np.abs(ride.v_mps * yaw)
    return np.where(np.isfinite(dx) & (np.hypot(dx, dy) > 1.0), out, np.nan)


def usable_intervals(ride: RideSeries, st: AeroSettings) -> np.ndarray:
    """Boolean per interval (i, i+1): the power balance without braking holds there."""
    dt = np.diff(ride.t_s)
    v, p = ride.v_mps, ride.power_w
    ok = (np.diff(ride.block) == 0) & (dt > 0) & (dt <= 2.0)
    ok &= (p[1:] >= st.min_power_w) & (p[:-1] >= st.min_power_w)
    ok &= (v[1:] >= st.min_speed_mps) & (v[:-1] >= st.min_speed_mps)
    with np.errstate(divide="ignore", invalid="ignore"):
        ok &= np.abs(np.diff(v) / dt) <= st.max_accel_mps2
    lat = lateral_accel_mps2(ride)
    ok &= ~(np.nan_to_num(lat[1:], nan=0.0) > st.max_lateral_mps2)
    # Erode: the seconds next to a coast, a sprint or a corner are rarely clean.
    bad = ~ok
    for shift in range(1, st.guard_s + 1):
        bad[shift:] |= ~ok[:-shift]
        bad[:-shift] |= ~ok[shift:]
    return ~bad


def _stretches(ok: np.ndarray, st: AeroSettings) -> list[tuple[int, int]]:
    """Runs of usable intervals as sample ranges [start, end], split and filtered."""
    out: list[tuple[int, int]] = []
    edges = np.diff(np.concatenate([[0], ok.astype(int), [0]]))
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
        # Intervals a..b-1 are usable: samples a..b.
        n_int = b - a
        pieces = max(1, int(np.ceil(n_int / st.max_stretch_s)))
        bounds = np.linspace(a, b, pieces + 1).round().astype(int)
        for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
            if hi - lo >= st.min_stretch_s:
                out.append((int(lo), int(hi)))
    return out


def _columns(ride: RideSeries, st: AeroSettings, lo: int, hi: int, m: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For samples lo..hi: y = recorded height minus the explained-by-power height, and
    the regressors of crr and CdA (cumulative from the stretch start), so that
    y = offset - crr * D - CdA * C."""
    g = GRAVITY_MPS2
    t, v = ride.t_s[lo:hi + 1], ride.v_mps[lo:hi + 1]
    p, rho = ride.power_w[lo:hi + 1], ride.rho_kgpm3[lo:hi + 1]
    dt = np.diff(t)
    work = st.drivetrain_efficiency * 0.5 * (p[1:] + p[:-1]) * dt - 0.5 * m * np.diff(v * v)
    d = 0.5 * (v[1:] + v[:-1]) * dt
    c = 0.25 * (rho[1:] + rho[:-1]) * 0.5 * (v[1:] ** 3 + v[:-1] ** 3) * dt / (m * g)
    cum = lambda a: np.concatenate([[0.0], np.cumsum(a)])  # noqa: E731
    y = ride.ele_m[lo:hi + 1] - ride.ele_m[lo] - cum(work) / (m * g)
    return y, cum(d), cum(c)


def _moments(cols: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> np.ndarray:
    """Per stretch, the demeaned cross products [DD, DC, CC, Dy, Cy, yy] (for OLS/bootstrap)."""
    out = np.empty((len(cols), 6))
    for k, (y, d, c) in enumerate(cols):
        y, d, c = y - y.mean(), d - d.mean(), c - c.mean()
        out[k] = (d @ d, d @ c, c @ c, d @ y, c @ y, y @ y)
    return out


def _rss(mom: np.ndarray, crr: np.ndarray | float, cda: np.ndarray | float) -> np.ndarray:
    """Residual sum of squares of y + crr D + CdA C from (summed) moments."""
    dd, dc, cc, dy, cy, yy = np.moveaxis(mom, -1, 0)
    return yy + 2 * crr * dy + 2 * cda * cy + crr ** 2 * dd + 2 * crr * cda * dc + cda ** 2 * cc


def _profile_mass(rides: list[RideSeries], spans: list[tuple[int, int, int]],
                  st: AeroSettings, picks: np.ndarray) -> tuple[float, float]:
    """Mass (and its bootstrap sd) minimising the virtual-elevation misfit, crr at the
    prior: mass is what climbs and accelerations pin down; crr and mass are nearly
    collinear, so both free would be unidentified."""
    grid = np.arange(st.mass_range_kg[0], st.mass_range_kg[1] + 1e-9, 1.0)
    mom = np.array([_moments([_columns(rides[k], st, lo, hi, m) for k, lo, hi in spans])
                    for m in grid])  # (mass, stretch, 6)

    def best(summed: np.ndarray) -> float:
        dc, cc, cy = summed[..., 1], summed[..., 2], summed[..., 4]
        cda = -(cy + st.crr_prior * dc) / cc
        return float(grid[int(np.argmin(_rss(summed, st.crr_prior, cda)))])

    estimate = best(mom.sum(axis=1))
    if estimate in (grid[0], grid[-1]):
        names = ", ".join(r.source for r in rides)
        raise CalibrationError(f"{names}: the mass is not identified by the ride (the best fit "
                               f"is at the edge of {st.mass_range_kg} kg); pass --mass-kg")
    boot = [best(mom[:, k].sum(axis=1)) for k in picks]
    return estimate, float(np.std(boot, ddof=1))


def _solve(mom: np.ndarray, crr_fixed: float | None) -> tuple[float, float]:
    """OLS of y = -crr D - CdA C (demeaned) from summed moments; crr given if fixed."""
    dd, dc, cc, dy, cy, _ = mom.sum(axis=0)
    if crr_fixed is not None:
        return crr_fixed, float(-(cy + crr_fixed * dc) / cc)
    a = np.array([[dd, dc], [dc, cc]])
    crr, cda = np.linalg.solve(a, -np.array([dy, cy]))
    return float(crr), float(cda)


def fit_aero(rides: list[RideSeries], st: AeroSettings) -> AeroFit:
    """CdA and crr of one rider from one or more rides (shared CdA, crr, mass).

    Without `st.mass_kg`, the mass is estimated first (`_profile_mass`) and its
    uncertainty is reported; CdA's bootstrap then holds the mass at that estimate.

    Raises:
        CalibrationError: fewer than 3 usable stretches (too much coasting, stopping or
            cornering); a mass the ride does not identify; a CdA no physical rider has
            (names the value and the likely cause); or a power balance that holds too
            exactly for a real road (a virtual ride's simulated speed), unless
            `st.allow_simulated`.
    """
    spans: list[tuple[int, int, int]] = []
    for k, ride in enumerate(rides):
        spans += [(k, lo, hi) for lo, hi in _stretches(usable_intervals(ride, st), st)]
    names = ", ".join(r.source for r in rides)
    if len(spans) < 3:
        raise CalibrationError(
            f"{names}: only {len(spans)} stretches of >= {st.min_stretch_s:.0f} s where the power "
            "balance holds (pedalling, moving, no braking or hard cornering); need at least 3")
    rng = np.random.default_rng(st.seed)
    picks = rng.integers(0, len(spans), size=(st.bootstrap, len(spans)))
    if st.mass_kg is None:
        mass, mass_std = _profile_mass(rides, spans, st, picks)
    else:
        mass, mass_std = float(st.mass_kg), 0.0
    cols = [_columns(rides[k], st, lo, hi, mass) for k, lo, hi in spans]
    mom = _moments(cols)
    crr, cda = _solve(mom, None)
    n = sum(len(c[0]) for c in cols)
    # The closest ANY (crr, CdA) gets: the test of a too-perfect (simulated) balance.
    rmse_free = float(np.sqrt(max(float(_rss(mom.sum(axis=0), crr, cda)), 0.0) / n))
    boot = np.array([_solve(mom[k], None) for k in picks])
    crr_std = float(np.std(boot[:, 0], ddof=1))
    lo_band, hi_band = st.crr_band
    note = "fitted"
    if st.mass_kg is None:
        note = f"mass estimated with crr at the prior {st.crr_prior} (mass and crr are collinear)"
    elif not lo_band <= crr <= hi_band:
        note = (f"fitted crr {crr:.4f} is outside [{lo_band}, {hi_band}]: the ride cannot "
                f"separate rolling from air drag; crr fixed to {st.crr_prior}")
    elif crr_std > 0.4 * crr:
        note = (f"fitted crr {crr:.4f} +- {crr_std:.4f} is not identified; crr fixed to "
                f"{st.crr_prior}")
    fixed = note != "fitted"
    if fixed:
        crr, cda = _solve(mom, st.crr_prior)
        boot = np.array([_solve(mom[k], st.crr_prior) for k in picks])
        crr_std = 0.0
    cda_std = float(np.std(boot[:, 1], ddof=1))
    rmse = float(np.sqrt(max(float(_rss(mom.sum(axis=0), crr, cda)), 0.0) / n))
    if not PHYSICAL_CDA_M2[0] <= cda <= PHYSICAL_CDA_M2[1]:
        raise CalibrationError(
            f"{names}: speed and power disagree with any physical rider: the best power "
            f"balance needs CdA {cda:.3f} m^2 (crr {crr:.4f}, mass {mass:.0f} kg), outside "
            f"{PHYSICAL_CDA_M2[0]}-{PHYSICAL_CDA_M2[1]} m^2. The speed is probably simulated "
            "(a virtual ride), or the mass or the power meter is wrong")
    if rmse_free < st.simulated_rmse_m and not st.allow_simulated:
        raise CalibrationError(
            f"{names}: the speed is simulated, not measured: power, speed and altitude obey "
            f"one power balance to {rmse_free:.2f} m RMS of virtual elevation over "
            f"{len(spans)} stretches (CdA {cda:.3f} m^2, mass {mass:.0f} kg), tighter than any "
            f"real altimeter and wind allow (>= {st.simulated_rmse_m} m). This is a virtual "
            "ride (Zwift and similar): its speed is the game's physics, not the rider's; "
            "--allow-virtual fits the game's rider anyway")
    first = [(lo, hi) for k, lo, hi in spans if k == 0]
    ve = _virtual_elevation(rides[0], cols[:len(first)], first, crr, cda)
    rho = float(np.mean(np.concatenate([r.rho_kgpm3 for r in rides])))
    used = float(sum(rides[k].t_s[hi] - rides[k].t_s[lo] for k, lo, hi in spans))
    return AeroFit(cda_m2=cda, cda_std_m2=cda_std, mass_kg=mass, mass_std_kg=mass_std,
                   mass_estimated=st.mass_kg is None, crr=crr, crr_std=crr_std,
                   crr_fixed=fixed, crr_note=note, used_s=used, n_stretches=len(spans),
                   rmse_m=rmse, air_density_kgpm3=rho, stretches=first, virtual_ele_m=ve)


def _virtual_elevation(ride: RideSeries, cols: list[tuple[np.ndarray, np.ndarray,
                       np.ndarray]], spans: list[tuple[int, int]], crr: float, cda: float
                       ) -> np.ndarray:
    """The fitted virtual elevation of `ride` on its samples (NaN off-stretch), each
    stretch shifted to the recorded altitude's mean (the fit's free offset)."""
    ve = np.full(len(ride), np.nan)
    for (lo, hi), (y, d, c) in zip(spans, cols, strict=True):
        rec = ride.ele_m[lo:hi + 1] - ride.ele_m[lo]
        virt = rec - y - crr * d - cda * c  # = work/(mg) - crr D - CdA C from the start
        ve[lo:hi + 1] = virt + np.mean(ride.ele_m[lo:hi + 1] - virt)
    return ve
