"""E9 over held powers (`wprime.e_n_along`, the loop of the live balance and of the
horizon's W' targets): each step is one Euler step of `e_n_rate`, capped at full, at the
floor if one is given; Skiba's recovery below CP against its closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from itt_planner.model.wprime import WPrimeModel, e_n_along, e_n_rate

CP_W, W_PRIME_J = 300.0, 20_000.0

steps = st.lists(st.tuples(st.floats(0.0, 900.0), st.floats(0.01, 2.0)), min_size=1,
                 max_size=60)


@settings(max_examples=60, deadline=None)
@given(e0=st.floats(0.0, 1.0), held=steps, model=st.sampled_from(list(WPrimeModel)),
       floor=st.one_of(st.none(), st.just(0.0)))
def test_each_step_is_an_euler_step_of_e9(e0: float, held: list[tuple[float, float]],
                                          model: WPrimeModel, floor: float | None) -> None:
    powers, dts = [p for p, _ in held], [h for _, h in held]
    e = e_n_along(e0, powers, dts, CP_W, W_PRIME_J, model, floor=floor)
    assert len(e) == len(held) + 1 and e[0] == e0
    for k, (p, h) in enumerate(held):
        step = e[k] + float(e_n_rate(e[k], p, CP_W, W_PRIME_J, model)) * h
        low = -math.inf if floor is None else floor
        assert e[k + 1] == pytest.approx(min(max(step, low), 1.0), abs=1e-12)
    assert np.all(e <= 1.0)
    if floor is not None:
        assert np.all(e >= floor)


def test_below_zero_only_without_a_floor() -> None:
    """A minute at CP + 500 W empties 30 kJ of a 20 kJ W': -0.5 free, 0 at the floor."""
    free = e_n_along(1.0, [CP_W + 500.0] * 60, [1.0] * 60, CP_W, W_PRIME_J)
    floored = e_n_along(1.0, [CP_W + 500.0] * 60, [1.0] * 60, CP_W, W_PRIME_J, floor=0.0)
    assert free[-1] == pytest.approx(-0.5) and floored[-1] == 0.0


def test_skiba_recovery_follows_its_closed_form() -> None:
    """At P < CP, Skiba's E_n recovers as 1 - (1 - e0) exp(-(CP - P) t / W')."""
    t = np.full(600, 0.5)
    e = e_n_along(0.2, [100.0] * 600, t.tolist(), CP_W, W_PRIME_J)
    exact = 1 - 0.8 * math.exp(-(CP_W - 100.0) * 300.0 / W_PRIME_J)
    assert e[-1] == pytest.approx(exact, abs=2e-3)
