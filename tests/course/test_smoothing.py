"""The altitude profile's fit (`course.smoothing.fit_altitude`) on samples as real fixes
give them: evenly spread while riding, bunched millimetres apart while standing."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from itt_planner.course.smoothing import ALTITUDE_MIN_GAP_M, fit_altitude, merge_close

_GRADE = 0.03


def _road(n_standing: int, at_m: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A 3 % road sampled every 5 m (0.3 m of altitude noise), and a standing rider's
    `n_standing` fixes projected within 4 cm of `at_m`, their altitude jittering by
    0.2 m (a barometer's steps)."""
    rng = np.random.default_rng(seed)
    s = np.arange(0.0, 3000.0, 5.0)
    stand = at_m + np.sort(rng.uniform(0.0, 0.04, n_standing))
    s_all = np.concatenate([s, stand])
    z = _GRADE * s_all + 0.3 * rng.standard_normal(len(s_all))
    z[len(s):] = _GRADE * at_m + 0.2 * rng.integers(-1, 2, n_standing)
    order = np.argsort(s_all)
    return s_all[order], z[order]


def test_a_standing_riders_fixes_make_no_wall() -> None:
    """The Strava GPX of the Ardennes ride ends with fixes 4 mm apart: its 250 m
    'smoothed' profile had grades of -53 % and +44 % there (the FIT's: -11.6 %)."""
    s, z = _road(40, 2990.0, 0)
    grid = np.arange(0.0, 2990.0, 1.0)
    for scale_m in (60.0, 250.0):
        slope = fit_altitude(s, z, 3000.0, False, scale_m, 0.25).derivative(1)(grid)
        assert np.abs(slope - _GRADE).max() < 0.01, scale_m


@settings(max_examples=25, deadline=None)
@given(n=st.integers(2, 200), at=st.floats(0.0, 2999.0), seed=st.integers(0, 1000))
def test_bunched_fixes_anywhere_keep_the_grade(n: int, at: float, seed: int) -> None:
    s, z = _road(n, at, seed)
    slope = fit_altitude(s, z, 3000.0, False, 250.0, 0.25).derivative(1)(
        np.arange(200.0, 2800.0, 1.0))
    assert np.abs(slope - _GRADE).max() < 0.01


def test_merged_samples_are_apart_and_keep_the_mean() -> None:
    s = np.array([0.0, 0.001, 0.002, 0.5, 1.2, 1.3, 5.0])
    z = np.array([1.0, 2.0, 3.0, 4.0, 10.0, 20.0, 7.0])
    sm, zm = merge_close(s, z, ALTITUDE_MIN_GAP_M)
    assert sm.tolist() == [0.0, 1.2, 5.0]
    assert zm.tolist() == [2.5, 15.0, 7.0]
