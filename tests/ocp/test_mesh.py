"""The OCP mesh (`ocp.mesh`): fine where the road bends, the slope changes, at the launch
and where the rider is slow; graded; exact end points; road data per interval that turns
and climbs exactly as much as the road."""

from __future__ import annotations

import numpy as np
import pytest
from support.courses import hairpin, straight

from itt_planner.course.builder import build_course
from itt_planner.course.geometry import Course
from itt_planner.ocp.course_nlp import cut_nodes
from itt_planner.ocp.mesh import (
    build_mesh,
    road_data,
    speed_spacing_m,
    split_spacing_m,
    target_spacing,
)

#: A flat straight, a 15 m hairpin, a 6 % climb and a descent: every rule of the mesh.
ROAD = build_course({"name": "mesh-test", "segments": [
    {"type": "straight", "length_m": 400},
    {"type": "arc", "angle_deg": 180, "radius_m": 15, "direction": "left"},
    {"type": "straight", "length_m": 300, "grade_pct": 6},
    {"type": "straight", "length_m": 300, "grade_pct": -4}]})


def _corner_mask(course: Course) -> np.ndarray:
    mask: np.ndarray = np.abs(course.kappa_per_m) > 0.5 / 15.0
    return mask


def test_speed_spacing_keeps_one_rk4_step_stable() -> None:
    """h 2a/v^2 = 1: the step halves when the speed drops by sqrt(2) at the same force."""
    v = np.array([0.5, 1.0, 5.0, 15.0])
    a = np.array([3.0, 3.0, 1.0, 0.5])
    h = speed_spacing_m(v, a)
    np.testing.assert_allclose(h * 2 * a / v ** 2, 1.0)
    assert h[0] == pytest.approx(0.5 ** 2 / 6)  # 4 cm at walking pace: the launch
    assert speed_spacing_m(np.array([10.0]), np.array([0.0]))[0] > 1e6  # no force: no limit


def test_target_spacing_is_fine_in_corners_and_coarse_on_straights() -> None:
    h = target_spacing(ROAD, 1.0, 10.0)
    corner = _corner_mask(ROAD)
    # ~0.1 rad of heading per interval: 1.5 m in a 15 m hairpin.
    assert h[corner].max() <= 0.1 * 15.0 + 1e-9
    assert h.min() >= 1.0  # never below h_min without a speed cap
    flat = (ROAD.s_m > 150) & (ROAD.s_m < 300)  # mid-straight, far from launch and corner
    assert h[flat].max() == pytest.approx(10.0)
    # Grade rule: the spacing changes by at most 0.25 m per m, so the fine zone spreads
    # into the braking zone before the hairpin.
    assert np.abs(np.diff(h)).max() <= 0.25 * ROAD.ds_m + 1e-9
    entry = ROAD.s_m[np.argmax(corner)]
    assert h[np.searchsorted(ROAD.s_m, entry - 10.0)] < 10.0


def test_target_spacing_is_fine_at_the_launch_and_where_the_slope_changes() -> None:
    h = target_spacing(ROAD, 1.0, 10.0)
    assert h[0] == pytest.approx(1.0)  # the launch: P/v is largest at the slowest speeds
    assert h[np.searchsorted(ROAD.s_m, 15.0)] < 10.0
    flat = straight(1500.0)
    assert target_spacing(flat, 1.0, 10.0)[-1] == pytest.approx(10.0)


def test_speed_cap_may_go_below_h_min_down_to_its_floor() -> None:
    course = straight(300.0)
    cap = np.full(len(course.s_m), 0.01)
    cap[course.s_m > 20] = np.inf
    h = target_spacing(course, 1.0, 10.0, h_cap_m=cap)
    assert h[0] == pytest.approx(0.05)  # 5 cm floor
    assert h[-1] == pytest.approx(10.0)


def test_build_mesh_spans_exactly_and_leaves_no_sliver() -> None:
    nodes = build_mesh(ROAD, 1.0, 10.0)
    assert nodes[0] == 0.0 and nodes[-1] == ROAD.length_m
    steps = np.diff(nodes)
    assert np.all(steps > 0)
    assert steps.max() <= 1.5 * 10.0 + 1e-9  # the last step absorbs < 1.5 steps
    # Steps follow the target spacing where they start.
    want = np.interp(nodes[:-1], ROAD.s_m, target_spacing(ROAD, 1.0, 10.0))
    np.testing.assert_allclose(steps[:-1], want[:-1], rtol=1e-9)
    # Fine in the hairpin (the heading turns by ~0.1 rad per interval at most), coarse on
    # the flat straight: far fewer nodes than a uniform 1 m mesh.
    turn = np.abs(np.diff(ROAD.at("theta_rad", nodes)))
    assert turn.max() <= 0.105
    assert len(nodes) < 0.4 * ROAD.length_m


def test_build_mesh_from_mid_course_and_uniform() -> None:
    rest = build_mesh(ROAD, 1.0, 10.0, start_m=512.3)
    assert rest[0] == 512.3 and rest[-1] == ROAD.length_m
    uniform = build_mesh(ROAD, uniform_m=2.0)
    np.testing.assert_allclose(np.diff(uniform), ROAD.length_m / (len(uniform) - 1))
    assert np.diff(uniform)[0] == pytest.approx(2.0, rel=0.01)
    # A uniform mesh honours a speed cap too: finer only where the cap asks for it.
    cap = np.where(ROAD.s_m < 10.0, 0.2, np.inf)
    capped = build_mesh(ROAD, uniform_m=2.0, h_cap_m=cap)
    assert np.diff(capped)[0] == pytest.approx(0.2)
    assert np.diff(capped)[len(capped) // 2] == pytest.approx(2.0)


@pytest.mark.parametrize("course", [ROAD, hairpin()], ids=["mesh-test", "hairpin"])
def test_road_data_turns_and_climbs_exactly_as_the_road(course: Course) -> None:
    nodes = build_mesh(course, 1.0, 10.0)
    kappa, beta, theta_mid, ds = road_data(course, nodes)
    np.testing.assert_allclose(ds, np.diff(nodes))
    # Heading: the discrete road turns by exactly the real road's heading change.
    turn = np.sum(kappa * ds)
    assert turn == pytest.approx(float(course.theta_rad[-1] - course.theta_rad[0]), abs=1e-9)
    # Height: the mean grades add up to the real climb.
    climb = np.sum(np.tan(beta) * ds)
    assert climb == pytest.approx(float(course.z_m[-1] - course.z_m[0]), abs=1e-9)
    mid = 0.5 * (nodes[1:] + nodes[:-1])
    np.testing.assert_allclose(theta_mid, course.at("theta_rad", mid))


def test_split_spacing_splits_just_the_named_intervals() -> None:
    """Intervals a plan's step did not resolve are halved (`cut_nodes` with the cap);
    their neighbours at most once more, the rest of the mesh stays."""
    nodes = build_mesh(ROAD, 1.0, 10.0)
    bad = [float(nodes[k]) for k in (5, 40, len(nodes) - 2)]
    cut = cut_nodes(nodes, 0.0, 0.0, ROAD.s_m, split_spacing_m(ROAD.s_m, nodes, bad))
    assert set(nodes) <= set(cut)
    for a in bad:
        i = int(np.searchsorted(nodes, a))
        assert np.sum((cut > a) & (cut < nodes[i + 1])) == 1  # split in two
        assert cut[np.searchsorted(cut, a) + 1] == pytest.approx(0.5 * (a + nodes[i + 1]))
    assert len(cut) - len(nodes) <= 2 * len(bad)
    same = cut_nodes(nodes, 0.0, 0.0, ROAD.s_m, split_spacing_m(ROAD.s_m, nodes, ()))
    assert np.array_equal(same, nodes)
