"""The 3D model's default guess (`ocp.guess.arc_guess`): a quasi-steady ride on a
least-curvature line whose speed, power, lean and W' agree with the path constraints
C15/C16, the road edges (C11) and W' >= 0."""

from __future__ import annotations

import numpy as np
import pytest

from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import build_3d
from itt_planner.model.params import ModelParams
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.guess import arc_guess
from itt_planner.ocp.mesh import build_mesh
from itt_planner.sim.hairpin import hairpin_course

RIDER = PRESETS["paper"]
COURSE = hairpin_course()
NODES = build_mesh(COURSE, 1.0, 10.0)
MODEL = build_3d()


def test_arc_guess_keeps_c15_c16_and_spends_w_prime() -> None:
    x, u = arc_guess(MODEL, COURSE, NODES, RIDER, Conditions(), 3.0)
    par = ModelParams(RIDER, Conditions()).vector()
    road = np.zeros((4, len(NODES)))  # the 3D's path constraints do not read the road
    path = np.asarray(MODEL.path.map(len(NODES))(x, road, par))  # friction - 1, pedal gate
    assert np.all(path <= 1e-9), "the guess breaks C16 or C15"
    row = {name: x[MODEL.index(name)] for name in MODEL.states}
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(u))
    assert np.all(row["e_n"] >= 0.0) and row["e_n"][-1] < 0.1, "W' is spent, never below 0"
    assert np.all(np.abs(row["w_n"]) <= 1.0)
    # It brakes into the 12 m hairpin (about 1.5 km) and pedals on the climb.
    kappa = np.abs(COURSE.at("kappa_per_m", NODES))
    hairpin = int(np.argmax(kappa))
    entry = NODES[hairpin]
    before = np.abs(NODES - (entry - 31.0)) <= 30.0  # the 60 m before the apex
    assert np.min(row["w_n"][before]) < -0.05
    assert np.mean(row["w_n"][NODES < 400]) * RIDER.max_power_w > RIDER.critical_power_w
    # Lean where the road turns, (nearly) upright on the straights: the line bends a
    # little there to set up the corners.
    assert np.abs(row["phi"][hairpin]) > 0.5 and np.abs(row["phi"][NODES < 400]).max() < 0.02
    # The line: on the road less the margin, from the centre of the start line, on the
    # outside before the hairpin (a left turn) and on its inside edge through it.
    margin = 0.5
    assert row["n"][0] == 0.0
    assert np.all(np.abs(row["n"]) <= COURSE.at("width_left_m", NODES) - margin + 1e-9)
    assert kappa[hairpin] > 0
    turn_in = NODES[kappa > 0.5 * kappa[hairpin]][0]
    before_turn_in = np.abs(NODES - (turn_in - 22.5)) < 17.5  # 40 m to 5 m before
    assert np.all(row["n"][before_turn_in] < -1.5)
    corner = np.abs(NODES - NODES[hairpin]) < 40
    assert np.max(row["n"][corner]) == pytest.approx(4.0 - margin)
