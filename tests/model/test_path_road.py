"""The path constraints take the road (`SpatialModel.path(x, road, par)`): the 3D and the
plain 1D ignore it, the 1D on a line (`build_1d_line`) reads the line's curvature into
C16 (a_y = v^2 kappa) and C15 (the steady lean); its ODE is the plain 1D's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from itt_planner.model.conditions import GRAVITY_MPS2, Conditions
from itt_planner.model.dynamics import (
    MODELS,
    build_1d,
    build_1d_line,
    build_3d,
    build_3d_steady_lean,
    build_model,
)
from itt_planner.model.params import ModelParams, lateral_limit_mps2
from itt_planner.model.rider import PRESETS

RIDER = PRESETS["paper"]
PAR = ModelParams(RIDER, Conditions()).vector()
STRAIGHT = np.array([0.0, 0.02, 0.3, 2.0])
BEND = np.array([1 / 20.0, 0.02, 0.3, 2.0])  # 20 m radius, left


def _g(model_path: object, x: np.ndarray, road: np.ndarray) -> np.ndarray:
    return np.asarray(model_path(x, road, PAR)).ravel()  # type: ignore[operator]


@pytest.mark.parametrize("build", [build_3d, build_3d_steady_lean, build_1d])
def test_models_with_their_own_lateral_state_ignore_the_road(build: object) -> None:
    model = build()  # type: ignore[operator]
    x = np.full(model.nx, 0.1)
    x[model.index("v")] = 12.0
    assert _g(model.path, x, BEND) == pytest.approx(_g(model.path, x, STRAIGHT), abs=0.0)


def test_1d_line_reads_the_curvature() -> None:
    line, plain = build_1d_line(), build_1d()
    assert line.states == plain.states and line.controls == plain.controls
    assert line.ode.name() != plain.ode.name()  # its own compiled kernels
    x, u = np.array([10.0, 0.3, 0.8]), np.array([0.2])
    # The same ODE (E3, E6, E9): the line's course carries slope and heading.
    for road in (STRAIGHT, BEND):
        for a, b in zip(line.ode(x, u, road, PAR), plain.ode(x, u, road, PAR), strict=True):
            assert np.asarray(a) == pytest.approx(np.asarray(b), rel=1e-12)
    # On the straight: C16 as the plain 1D's, C15 open (upright, W_n 0.3 < 1).
    g = _g(line.path, x, STRAIGHT)
    assert g[0] == pytest.approx(_g(plain.path, x, STRAIGHT)[0], rel=1e-12)
    assert g[1] < 0
    # In the bend: a_y = v^2 kappa in C16, and the steady lean closes C15 at 5 m/s^2.
    g = _g(line.path, x, BEND)
    ay = 10.0 ** 2 / 20.0
    lon = np.asarray(plain.path(x, STRAIGHT, PAR)).item() + 1
    assert g[0] == pytest.approx(lon + (ay / lateral_limit_mps2(RIDER, Conditions())) ** 2 - 1)
    assert math.degrees(math.atan(ay / GRAVITY_MPS2)) > math.degrees(RIDER.pedal_lean_max_rad)
    assert g[1] == pytest.approx(0.3, abs=0.02)  # W_n over a closed gate
    y = np.asarray(line.outputs(x, BEND, PAR)).ravel()
    assert y[2] == pytest.approx(ay)  # reported lateral acceleration
    # Signed like the curvature: a right-hand bend is the mirror image.
    right = BEND * np.array([-1, 1, 1, 1])
    assert _g(line.path, x, right) == pytest.approx(g)


def test_build_model_by_name() -> None:
    assert MODELS == ("3d", "1d", "1dline")
    assert [build_model(name).name for name in MODELS] == list(MODELS)
    with pytest.raises(ValueError, match="1dline"):
        build_model("2d")
