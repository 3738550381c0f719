"""Calibration: known truth recovered from the virtual rider's rides, real rides in range or
refused with the reason, and the output rider loads with `--rider`."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from support.calibration_ride import ALT_M, TRUTH, calibration_course, effort_plan, sensor_recording

from itt_planner.calibration import (
    AeroSettings,
    CalibrationError,
    CalibrationOptions,
    calibrate,
    fit_aero,
    fit_cp,
    prepare_ride,
    rider_yaml,
    write_rider,
)
from itt_planner.calibration.calibrate import CalibrationResult, load_rides, write_setup_riders
from itt_planner.calibration.power_curve import submaximal_warning
from itt_planner.calibration.ride_data import fill_sparse_records
from itt_planner.course.geometry import Course
from itt_planner.course.track_files import Recording
from itt_planner.model.conditions import Conditions, air_density_kgpm3
from itt_planner.model.rider import load_rider
from itt_planner.sim import simulate_ride, smart_recording

#: The synthetic course and the virtual rider's recording on it.
Synthetic = tuple[Course, Recording]


@pytest.fixture(scope="module")
def synthetic() -> Synthetic:
    """One ride of the virtual rider (3D model, sensor noise) with the truth `TRUTH`."""
    course = calibration_course()
    # The air of the ride as the calibration will compute it (ISA at the altitude, 15 C).
    rho = float(air_density_kgpm3(ALT_M + 30.0, 15.0))
    # 0.2 s steps (5 RK4 substeps each) halve the ride's cost; sensors still fire at 1 Hz.
    sim = simulate_ride(course, TRUTH, effort_plan(course, TRUTH), policy="open_loop", seed=3,
                        conditions=Conditions(air_density_kgpm3=rho), dt_s=0.2)
    return course, sensor_recording(sim, np.random.default_rng(4))


def test_air_density_isa() -> None:
    assert float(air_density_kgpm3(0.0, 15.0)) == pytest.approx(1.225, abs=0.002)
    assert float(air_density_kgpm3(1000.0, 15.0)) < float(air_density_kgpm3(0.0, 15.0))


def test_cp_models_recover_an_exact_curve() -> None:
    mmp = {d: 300.0 + 20000.0 / d for d in (60, 120, 180, 300, 480, 600, 900, 1200)}
    fit = fit_cp(mmp, "2p")
    assert fit.cp_w == pytest.approx(300.0, rel=1e-3)
    assert fit.w_prime_j == pytest.approx(20000.0, rel=1e-3)
    assert fit.durations_s[0] >= 120


def test_a_flat_power_curve_warns_that_cp_and_w_prime_are_not_the_riders() -> None:
    """An evenly paced time trial's curve (W' 2.6 kJ, as the Zwift Bologna TT's) is
    fitted and warned about; a rider's maximal curve (W' 20 kJ) is not."""
    flat = {d: 292.0 + 2600.0 / d for d in (120, 180, 300, 480, 600, 900, 1200)}
    why = submaximal_warning(fit_cp(flat, "2p"), flat)
    assert why is not None and "W' 2.6 kJ" in why and "no maximal effort" in why
    assert "all-out efforts" in why
    maximal = {d: 300.0 + 20000.0 / d for d in (120, 180, 300, 480, 600, 900, 1200)}
    assert submaximal_warning(fit_cp(maximal, "2p"), maximal) is None


def test_cp_refuses_a_short_ride() -> None:
    with pytest.raises(CalibrationError, match="too short"):
        fit_cp({60: 400.0, 120: 350.0, 180: 340.0}, "2p")


def test_refusals_name_the_reason(synthetic: Synthetic) -> None:
    _, rec = synthetic
    no_power = dataclasses.replace(rec, power_w=None)
    with pytest.raises(CalibrationError, match="no power"):
        prepare_ride(no_power)
    flat = dataclasses.replace(rec, ele_m=np.full(len(rec), np.nan))
    with pytest.raises(CalibrationError, match="no elevation"):
        prepare_ride(flat)
    assert rec.time_s is not None and rec.speed_mps is not None and rec.power_w is not None
    short = Recording(path=rec.path, sha256="", lat_deg=rec.lat_deg[:300],
                      lon_deg=rec.lon_deg[:300], ele_m=rec.ele_m[:300], time_s=rec.time_s[:300],
                      speed_mps=rec.speed_mps[:300], power_w=rec.power_w[:300])
    with pytest.raises(CalibrationError, match="too short"):
        prepare_ride(short)


def test_synthetic_truth_recovered(synthetic: Synthetic, tmp_path: Path) -> None:
    """CdA and CP within 5 %, crr and W' within 15 % (issue 15), mass given."""
    course, rec = synthetic
    result = calibrate([rec], CalibrationOptions(mass_kg=TRUTH.mass_kg), courses=[course])
    assert result.aero is not None and result.cp_2p is not None, result.refusals
    assert result.aero.cda_m2 == pytest.approx(TRUTH.drag_area_m2, rel=0.05)
    assert not result.aero.crr_fixed, result.aero.crr_note
    assert result.aero.crr == pytest.approx(TRUTH.crr, rel=0.15)
    assert result.cp_2p.cp_w == pytest.approx(TRUTH.critical_power_w, rel=0.05)
    assert result.cp_2p.w_prime_j == pytest.approx(TRUTH.w_prime_j, rel=0.15)
    assert 0 < result.aero.cda_std_m2 < 0.05 and result.cp_2p.cp_std_w > 0
    # Still air in the simulation: the fitted wind is small.
    assert float(np.hypot(*result.aero.wind_mps[0])) < 1.0
    # The rider file loads as `--rider` and carries the fitted values.
    rider = load_rider(write_rider(result, tmp_path / "me.yaml"))
    assert rider.drag_area_m2 == pytest.approx(result.aero.cda_m2, rel=1e-5)
    assert rider.critical_power_w == pytest.approx(result.cp_2p.cp_w, rel=1e-5)
    assert rider.mass_kg == TRUTH.mass_kg


def test_smart_recording_truth_recovered(synthetic: Synthetic) -> None:
    """The same bars as above on the ride with 3 of 4 records dropped (gaps of 1-7 s, as
    smart recording writes): split at every gap over 5 s, the ride was refused (aero: 0
    stretches; CP: longest effort 45 s on the real St John's ride thinned alike)."""
    course, rec = synthetic
    sparse = smart_recording(rec, seed=5)
    assert len(sparse) < 0.3 * len(rec)
    result = calibrate([sparse], CalibrationOptions(mass_kg=TRUTH.mass_kg), courses=[course])
    assert result.aero is not None and result.cp_2p is not None, result.refusals
    assert result.rides[0].filled_s > 2 * len(sparse)
    assert result.aero.cda_m2 == pytest.approx(TRUTH.drag_area_m2, rel=0.05)
    assert result.aero.crr == pytest.approx(TRUTH.crr, rel=0.15)
    assert result.cp_2p.cp_w == pytest.approx(TRUTH.critical_power_w, rel=0.05)
    assert result.cp_2p.w_prime_j == pytest.approx(TRUTH.w_prime_j, rel=0.15)


def test_only_gaps_ridden_through_are_filled(synthetic: Synthetic) -> None:
    _, rec = synthetic
    assert fill_sparse_records(rec)[1] == 0  # 1 Hz: untouched
    assert rec.time_s is not None
    # Records 100-109 dropped while riding (filled back at 1 s); at 200-209 the rider
    # stands (the position held): a pause, left as a gap.
    lat, lon = rec.lat_deg.copy(), rec.lon_deg.copy()
    lat[200:211], lon[200:211] = lat[200], lon[200]
    drop = np.r_[100:110, 201:210]
    stood = dataclasses.replace(
        rec, lat_deg=np.delete(lat, drop), lon_deg=np.delete(lon, drop),
        time_s=np.delete(rec.time_s, drop), ele_m=np.delete(rec.ele_m, drop),
        speed_mps=None, power_w=None, cadence_rpm=None)
    filled, added = fill_sparse_records(stood)
    assert added == 10 and filled.time_s is not None
    np.testing.assert_allclose(filled.time_s[:200], rec.time_s[:200])
    assert filled.time_s[201] - filled.time_s[200] == pytest.approx(10.0)


def test_an_indoor_ride_gives_its_power_to_cp_and_w_prime(synthetic: Synthetic,
                                                         tmp_path: Path) -> None:
    """A trainer's ride (power and stamps; no GPS, altitude or speed) was refused whole
    ("no elevation in the record"), CP and W' with it, though a CP test is often ridden
    indoors: its power now goes into the power-duration curve, and only the power
    balance and the cornering refuse it, saying why."""
    course, rec = synthetic
    nan = np.full(len(rec), np.nan)
    indoor = dataclasses.replace(rec, path=Path("trainer.fit"), lat_deg=nan, lon_deg=nan,
                                 ele_m=nan, speed_mps=None)
    alone = calibrate([indoor], CalibrationOptions(mass_kg=TRUTH.mass_kg))
    assert alone.cp_2p is not None
    assert alone.cp_2p.cp_w == pytest.approx(TRUTH.critical_power_w, rel=0.05)
    assert alone.refusals["aero"] == ("no ride with altitude and speed: trainer.fit: no "
                                      "elevation in the record; the power balance needs the "
                                      "climbing work")
    assert alone.refusals["cornering"] == "no ride with GPS positions and speed"
    assert alone.as_dict()["power_only"] == {"trainer.fit": alone.power_rides[0].why}
    assert "# power only trainer.fit: no elevation" in rider_yaml(alone)
    both = calibrate([indoor, rec], CalibrationOptions(mass_kg=TRUTH.mass_kg),
                     courses=[course])
    assert both.aero is not None and [r.source for r in both.rides] == [str(rec.path)]
    assert both.sources == [str(rec.path), "trainer.fit"]
    assert both.mmp_w == alone.mmp_w  # the same power twice: the same best efforts
    load_rider(write_rider(both, tmp_path / "me.yaml"))


def test_synthetic_mass_estimated(synthetic: Synthetic) -> None:
    """Without --mass-kg the climbs give the mass (crr at its prior) and CdA stays close."""
    course, rec = synthetic
    result = calibrate([rec], CalibrationOptions(), courses=[course])
    assert result.aero is not None and result.aero.mass_estimated
    assert result.aero.mass_kg == pytest.approx(TRUTH.mass_kg, rel=0.05)
    assert result.aero.cda_m2 == pytest.approx(TRUTH.drag_area_m2, rel=0.1)


def test_synthetic_corners_read(synthetic: Synthetic) -> None:
    """Every 20 m corner is found; the virtual rider takes them at the top of a climb,
    power-limited, so the lateral acceleration USED is below its grip (0.92 mu_y g)."""
    course, rec = synthetic
    result = calibrate([rec], CalibrationOptions(mass_kg=TRUTH.mass_kg), courses=[course])
    assert result.cornering is not None, result.refusals
    assert len(result.cornering.corners) == 9
    assert all(c.radius_m == pytest.approx(20.0, rel=0.25) for c in result.cornering.corners)
    assert 0 < result.cornering.max_lateral_accel_mps2 < 0.92 * 9.81


@pytest.mark.parametrize("name", ["rides/edge810_vector_stjohns_2013.fit",
                                  "rides/edge1000_ardennes_2019.fit",
                                  "rides/sauerland_2025.fit"])
def test_real_ride_cda_plausible(data_file: Callable[[str], Path], name: str) -> None:
    """Real rides: CdA in 0.18-0.45 m^2 with its uncertainty (mass estimated, wind fitted)."""
    fit = fit_aero(load_rides([data_file(name)], None), AeroSettings())
    assert 0.18 <= fit.cda_m2 <= 0.45
    assert 0 < fit.cda_std_m2 < 0.1
    assert 50 < fit.mass_kg < 140 and fit.mass_std_kg > 0


@pytest.mark.slow
def test_stop_and_go_ride_with_a_drifting_altitude(data_file: Callable[[str], Path]) -> None:
    """The flat Shanghai ride ends where it started 85 m higher: its altitude is not the
    road's, so no CdA or crr is fitted from it (mass given or not: its crr 0.008 was that
    drift read as rolling); CP and W' (power only) still are."""
    path = data_file("rides/elemnt_shanghai_2019_stopgo.fit")
    result = calibrate([path], CalibrationOptions(mass_kg=80.0))
    assert result.aero is None and "the altitude is not the road's" in result.refusals["aero"]
    assert result.cp_2p is not None


def test_virtual_ride_is_refused_as_simulated(data_file: Callable[[str], Path]) -> None:
    """Zwift's speed obeys one power balance too exactly for a real road: refused. So
    does a phone app's power estimated from speed and altitude (Urban Biker's GPX from
    GoldenCheetah's tests, 0.20 m): the refusal names both."""
    path = data_file("rides/zwift_bologna_tt_virtual.tcx")
    result = calibrate([path], CalibrationOptions())
    assert "speed is simulated" in result.refusals["aero"]
    assert "an app's power estimated from speed and altitude" in result.refusals["aero"]
    # An evenly paced TT: CP and W' are fitted, with a warning (W' 2.6 kJ).
    assert result.cp_2p is not None and "no maximal effort" in result.warnings["cp_2p"]
    forced = calibrate([path], CalibrationOptions(allow_virtual=True))
    assert forced.aero is not None and forced.aero.rmse_m < 0.5


def test_cda_per_setup(synthetic: Synthetic, tmp_path: Path) -> None:
    """Two rides, two setups (issue 15, "CdA per position or bike"): the second ride is
    the first with the power a CdA 0.05 m^2 larger needs at the same speeds (still air,
    as simulated). One CdA per setup, crr and mass shared; a rider file per setup."""
    _, rec = synthetic
    assert rec.speed_mps is not None and rec.power_w is not None
    rho = air_density_kgpm3(rec.ele_m, 15.0)
    v = np.nan_to_num(rec.speed_mps)
    upright = dataclasses.replace(rec, path=Path("synthetic-upright.csv"),
                                  power_w=rec.power_w + 0.5 * rho * 0.05 * v ** 3)
    rides = load_rides([rec, upright], None)
    fit = fit_aero(rides, AeroSettings(mass_kg=TRUTH.mass_kg, setup_of_ride=(0, 1),
                                       bootstrap=20))
    tt, up = fit.setup_cda_m2
    assert tt == pytest.approx(TRUTH.drag_area_m2, rel=0.05) and fit.cda_m2 == tt
    assert up - tt == pytest.approx(0.05, rel=0.1)
    assert all(0 < sd < 0.02 for sd in fit.setup_cda_std_m2)
    result = CalibrationResult(sources=[r.source for r in rides],
                               rider=dataclasses.replace(TRUTH, drag_area_m2=tt), rides=rides,
                               aero=fit, setup_names=["tt", "upright"], setup_of_ride=[0, 1])
    assert result.as_dict()["setups"]["upright"]["cda_m2"] == pytest.approx(up, abs=1e-4)
    written = write_setup_riders(result, tmp_path / "me.yaml")
    assert [p.name for p in written] == ["me.tt.yaml", "me.upright.yaml"]
    assert load_rider(written[1]).drag_area_m2 == pytest.approx(up, rel=1e-5)
    with pytest.raises(CalibrationError, match="one --setup per ride"):
        calibrate([rec, upright], CalibrationOptions(setups=("tt",)))


@pytest.mark.parametrize(("crr", "mass_kg", "said"),
                         [(0.06, TRUTH.mass_kg, "crr 0.060 and CdA 0.29"),
                          (0.05, None, "at 80 kg it needs crr 0.04")])
def test_an_unpaved_ride_is_refused_for_its_rolling_resistance(
        synthetic: Synthetic, crr: float, mass_kg: float | None, said: str) -> None:
    """The virtual rider's ride with the power a mountain-bike trail's crr asks for (two real
    MTB rides' best balance at crr 0.004 needed CdA 0.63, and the refusal blamed a virtual
    ride): refused, saying that with crr free (at the given mass, else 80 kg) the balance
    needs a rolling resistance no road has and a rider's CdA. (At crr 0.02 the CdA is 0.40
    and nothing is refused: a heavier rider on tarmac looks the same, see README.)"""
    _, rec = synthetic
    assert rec.power_w is not None and rec.speed_mps is not None
    rolling_w = (crr - TRUTH.crr) * TRUTH.mass_kg * 9.81 * np.nan_to_num(rec.speed_mps)
    trail = dataclasses.replace(rec, power_w=rec.power_w + rolling_w)
    with pytest.raises(CalibrationError, match="disagree with any physical rider") as refusal:
        fit_aero(load_rides([trail], None), AeroSettings(mass_kg=mass_kg))
    message = str(refusal.value)
    assert "no road tyre on tarmac" in message and said in message, message
