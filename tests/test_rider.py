"""Rider presets and YAML overrides (model.md section 7)."""

from __future__ import annotations

from pathlib import Path

import pytest

from itt_planner.errors import RiderError
from itt_planner.rider import PRESETS, Rider, load_rider


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
