"""The rider file `calibrate` writes reads back with each value's uncertainty and source."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from itt_planner.calibration import CalibrationResult, fit_cp, rider_yaml
from itt_planner.calibration.calibrate import YAML_HEADER
from itt_planner.calibration.rider_file import read_calibrated_rider
from itt_planner.model.rider import PRESETS, load_rider


def cp_only_result() -> CalibrationResult:
    """A calibration whose only fit is CP/W' (of an exact 2-parameter curve); aero and
    cornering refused."""
    mmp = {int(t): 280.0 + 18000.0 / t for t in np.geomspace(60, 1800, 12)}
    cp = fit_cp(mmp, "2p")
    rider = dataclasses.replace(PRESETS["paper"], name="me", critical_power_w=cp.cp_w,
                                w_prime_j=cp.w_prime_j)
    return CalibrationResult(sources=["a.fit", "b.fit"], rider=rider, rides=[], mmp_w=mmp,
                             cp_2p=cp, refusals={"aero": "too short", "cornering": "no corner"},
                             warnings={"cp_2p": "W' 1.0 kJ is outside"})


def test_calibrated_rider_reads_back(tmp_path: Path) -> None:
    result = cp_only_result()
    path = tmp_path / "me.yaml"
    path.write_text(rider_yaml(result), encoding="utf-8")
    cal = read_calibrated_rider(path)
    assert cal is not None
    assert cal.sources == ("a.fit", "b.fit")
    assert cal.refusals == {"aero": "too short", "cornering": "no corner"}
    assert cal.warnings == {"cp_2p": "W' 1.0 kJ is outside"}
    assert not any(line.startswith("warning") for line in cal.conditions)
    # The values are the rider `--rider` loads; the notes say where they came from.
    rider = load_rider(str(path))
    assert cal.values["critical_power_w"] == rider.critical_power_w
    assert abs(rider.critical_power_w - 280.0) < 1.0
    assert "2-parameter model" in cal.notes["critical_power_w"]
    assert cal.notes["w_prime_j"].startswith("+- ")
    assert "drag_area_m2" not in cal.notes  # aero refused: the preset's value, no note


def test_other_riders_are_not_calibrated(tmp_path: Path) -> None:
    hand = tmp_path / "hand.yaml"
    hand.write_text("preset: paper\ncritical_power_w: 300  # my guess\n", encoding="utf-8")
    assert read_calibrated_rider(hand) is None
    assert read_calibrated_rider("paper") is None  # a preset name
    assert rider_yaml(cp_only_result()).startswith(YAML_HEADER)
