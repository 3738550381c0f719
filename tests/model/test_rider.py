"""Rider presets and YAML overrides (model.md section 7)."""

from __future__ import annotations

from pathlib import Path

import pytest

from itt_planner.errors import RiderError
from itt_planner.model.rider import PRESETS, Rider, load_rider


def test_presets_are_the_paper_rider_and_three_virtual_riders() -> None:
    assert set(PRESETS) == {"paper", "typical", "specialist", "climber"}
    assert load_rider("paper") == Rider()
    assert load_rider("paper").mass_kg == 77.0 and load_rider("paper").critical_power_w == 440.0
    assert load_rider("specialist").mass_kg == 88.0
    climber = load_rider("climber")
    assert climber.mass_kg == 61.0
    # Smaller frontal area: less drag than the paper rider.
    assert climber.drag_area_m2 < PRESETS["paper"].drag_area_m2
    assert all(p.critical_power_w < p.max_power_w for p in PRESETS.values())


def test_yaml_overrides_fields_of_a_preset(tmp_path: Path) -> None:
    path = tmp_path / "me.yaml"
    path.write_text("preset: climber\nmass_kg: 64.5\ncritical_power_w: 300\n")
    rider = load_rider(path)
    assert rider.name == "me"
    assert rider.mass_kg == 64.5 and rider.critical_power_w == 300
    assert rider.drag_area_m2 == PRESETS["climber"].drag_area_m2


@pytest.mark.parametrize(("text", "field"), [
    ("mass_kg: -70\n", "mass_kg"),
    ("crr: 0.5\n", "crr"),
    ("critical_power_w: 2000\n", "critical_power_w"),
    ("w_prime_j: .nan\n", "w_prime_j"),
    ("wingspan_m: 2\n", "wingspan_m"),
    ("preset: sprinter\n", "unknown preset"),
    ("- a list\n", "mapping"),
])
def test_invalid_yaml_names_the_field(tmp_path: Path, text: str, field: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(RiderError, match=field) as info:
        load_rider(path)
    assert "bad.yaml" in str(info.value)


def test_unknown_preset_name() -> None:
    with pytest.raises(RiderError, match="not a preset"):
        load_rider("eddy")


def test_cornering_limit_and_drivetrain_fields_from_yaml(tmp_path: Path) -> None:
    """The calibration's field names (issue 14 item 4): loadable, validated, defaults
    that keep the paper's model."""
    assert Rider().max_lateral_accel_mps2 is None and Rider().drivetrain_efficiency == 1.0
    path = tmp_path / "amateur.yaml"
    path.write_text("preset: typical\nmax_lateral_accel_mps2: 4.5\ndrivetrain_efficiency: 0.97\n")
    rider = load_rider(path)
    assert rider.max_lateral_accel_mps2 == 4.5 and rider.drivetrain_efficiency == 0.97
    path.write_text("max_lateral_accel_mps2: null\n")
    assert load_rider(path).max_lateral_accel_mps2 is None


@pytest.mark.parametrize(("text", "field"), [
    ("max_lateral_accel_mps2: 0\n", "max_lateral_accel_mps2"),
    ("max_lateral_accel_mps2: .inf\n", "max_lateral_accel_mps2"),
    ("drivetrain_efficiency: 1.2\n", "drivetrain_efficiency"),
    ("drivetrain_efficiency: 0.1\n", "drivetrain_efficiency"),
])
def test_invalid_cornering_and_drivetrain_fields(tmp_path: Path, text: str, field: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(RiderError, match=field):
        load_rider(path)


def test_lateral_limit_is_the_lower_of_grip_and_rider() -> None:
    from itt_planner.model.conditions import Conditions
    from itt_planner.model.params import PARAMS, ModelParams, lateral_limit_mps2

    assert lateral_limit_mps2(Rider(), Conditions()) == pytest.approx(9.81)
    timid = Rider(max_lateral_accel_mps2=4.0)
    assert lateral_limit_mps2(timid, Conditions()) == 4.0
    assert lateral_limit_mps2(timid, Conditions(mu_y=0.3)) == pytest.approx(0.3 * 9.81)
    par = ModelParams(timid, Conditions()).vector()
    assert par[PARAMS.index("mu_y")] == pytest.approx(4.0 / 9.81)
