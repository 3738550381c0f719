"""The horizon's soft terminal W' target (`HorizonWindow.terminal_e_n`): the rider's
deviation from the plan carried to the window's end through E9, never above full W'; and
a cold start's W' (`HorizonWindow.anchor`) ridden the same way.

The plan here recovers W' at a steady power below CP from empty, so E9 (Skiba) has a
closed form: `1 - E_n` decays as `exp(-(CP - P) t / W')`. Riding that plan's power from
`e0` leaves `1 - (1 - e0) exp(-(CP - P) T / W')` at the window's end.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.courses import hairpin

from itt_planner.model.conditions import Conditions
from itt_planner.model.dynamics import build_3d_steady_lean
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.horizon_window import HorizonWindow
from itt_planner.ocp.plan import Plan

COURSE = hairpin(straight_m=600.0)
RIDER = PRESETS["paper"]
#: The recovering plan's steady power: coasting.
POWER_W = 0.0


@pytest.fixture(scope="module")
def window() -> HorizonWindow:
    """A window over a plan that starts with W' empty and recovers it at `POWER_W`."""
    plan = solve_plan(COURSE, RIDER, model="1d")
    e_n = 1.0 - np.exp(-(RIDER.critical_power_w - POWER_W) * plan.t_s / RIDER.w_prime_j)
    recovering: Plan = dataclasses.replace(plan, power_w=np.full_like(plan.s_m, POWER_W),
                                           e_n=e_n, w_prime_j=e_n * RIDER.w_prime_j)
    return HorizonWindow(build_3d_steady_lean(), COURSE, RIDER, recovering, Conditions(),
                         HorizonSettings(horizon_m=500.0, max_window_s=0.0))


def ridden_plan(window: HorizonWindow, nodes: np.ndarray, e0: float) -> float:
    """E_n at the window's end after riding the plan's power from `e0` (closed form)."""
    t = float(window.plan.at("t_s", nodes[-1]) - window.plan.at("t_s", nodes[0]))
    return 1.0 - (1.0 - e0) * math.exp(-(RIDER.critical_power_w - POWER_W) * t / RIDER.w_prime_j)


def beyond(nodes: np.ndarray) -> float:
    return float((COURSE.length_m - nodes[-1]) / (COURSE.length_m - nodes[0]))


@settings(max_examples=30, deadline=None)
@given(e0=st.floats(0.0, 1.0), s0=st.floats(0.0, 1200.0))
def test_the_target_is_the_plans_power_ridden_from_the_riders_w_prime(
        window: HorizonWindow, e0: float, s0: float) -> None:
    nodes = window.nodes(s0)
    plan_end = float(window.plan.at("e_n", nodes[-1]))
    expected = plan_end + (ridden_plan(window, nodes, e0)
                           - ridden_plan(window, nodes, float(window.plan.at("e_n", s0))))
    expected = plan_end + (expected - plan_end) * beyond(nodes)
    target = window.terminal_e_n(nodes, e0)
    assert 0.0 <= target <= 1.0
    # Euler steps of the plan's ~1 s intervals against the closed form
    assert target == pytest.approx(expected, abs=2e-3)


def test_a_surplus_over_an_empty_plan_asks_for_no_more_than_riding_the_plan_leaves(
        window: HorizonWindow) -> None:
    """The Sauerland case (bench/RESULTS.md, 2026-12-03): the plan emptied W', the rider
    kept most of it. Added as it is, the surplus asked for more than full W' at the end."""
    nodes = window.nodes(0.0)
    plan_end = float(window.plan.at("e_n", nodes[-1]))
    added = plan_end + 0.9 * beyond(nodes)
    target = window.terminal_e_n(nodes, 0.9)
    assert added > 1.0
    assert plan_end < target <= ridden_plan(window, nodes, 0.9) + 2e-3


def test_a_cold_start_rides_the_plans_power_from_the_riders_w_prime(
        window: HorizonWindow) -> None:
    """The start from the plan, re-anchored at a rider with W' to spare, recovers as E9
    does from there (what the terminal target asks for), not the plan's recovery shifted:
    shifted, it ran above full W' and was no start of the NLP (on the Sauerland ride's
    km-33 windows, 15 of 35 cold replans failed; bench/RESULTS.md, 2026-12-03)."""
    nodes = window.nodes(100.0)
    x, _ = window.plan_guess(nodes)
    ie = window.model.index("e_n")
    x0 = x[:, 0].copy()
    x0[ie] = 0.9
    lo, hi = np.full_like(x, -np.inf), np.full_like(x, np.inf)
    anchored = window.anchor(nodes, x, x0, lo, hi)[ie]
    expected = [ridden_plan(window, nodes[: k + 1], 0.9) for k in range(len(nodes))]
    assert anchored == pytest.approx(expected, abs=2e-3)
    assert window.terminal_e_n(nodes, 0.9) <= anchored[-1] + 1e-9
