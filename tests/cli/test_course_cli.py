"""`itt-planner course info|save`: JSON contract, human text, errors without traceback."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from typer.testing import CliRunner

from itt_planner.cli import app

runner = CliRunner()
KEYS = {"length_m", "gain_m", "loss_m", "max_grade", "min_grade", "n_corners", "min_radius_m",
        "closed_loop", "corners"}
CORNER_KEYS = {"apex_s_m", "entry_s_m", "exit_s_m", "min_radius_m", "angle_deg", "direction"}


def test_info_json_on_a_gps_track(data_file: Callable[[str], Path]) -> None:
    path = data_file("courses/tokyo2020_olympic_itt_lap.csv")
    result = runner.invoke(app, ["course", "info", str(path), "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    assert set(info) >= KEYS
    assert info["closed_loop"] is True
    assert info["n_corners"] == len(info["corners"]) > 0
    assert all(set(c) == CORNER_KEYS for c in info["corners"])
    assert info["gain_m"] == pytest.approx(info["loss_m"], rel=0.02)


def test_info_human_text_on_a_demo() -> None:
    result = runner.invoke(app, ["course", "info", "verona-like"])
    assert result.exit_code == 0
    assert "16.80 km" in result.stdout and "SYNTHETIC" in result.stdout


def test_save_then_info(tmp_path: Path) -> None:
    out = tmp_path / "v.course.npz"
    result = runner.invoke(app, ["course", "save", "verona-like", "-o", str(out), "--json"])
    assert result.exit_code == 0
    assert json.loads(result.stdout)["output"] == str(out)
    info = json.loads(runner.invoke(app, ["course", "info", str(out), "--json"]).stdout)
    assert info["length_m"] == pytest.approx(16_800, rel=0.01)


@pytest.mark.parametrize(("name", "text"), [
    ("empty.gpx", ""), ("short.csv", "11,45,1\n11.0001,45,1\n"), ("same.csv", "11,45,1\n" * 9),
    ("nan.csv", "lat,lon\nnan,nan\nnan,nan\nnan,nan\n"), ("junk.tcx", "not xml"),
])
def test_bad_input_exits_nonzero_with_one_json_error(tmp_path: Path, name: str, text: str) -> None:
    path = tmp_path / name
    path.write_text(text)
    result = runner.invoke(app, ["course", "info", str(path), "--json"])
    assert result.exit_code == 1
    assert result.exception is None or isinstance(result.exception, SystemExit)
    err = json.loads(result.stdout)
    assert name in err["error"] and err["type"] == "CourseError"


def test_subprocess_error_has_no_traceback(tmp_path: Path) -> None:
    path = tmp_path / "empty.fit"
    path.write_bytes(b"")
    proc = subprocess.run([sys.executable, "-c", "from itt_planner.cli import main; main()",
                           "course", "info", str(path)],
                          capture_output=True, text=True, check=False)
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr
    assert "empty.fit" in proc.stderr and "empty" in proc.stderr
