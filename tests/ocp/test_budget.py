"""The full-course solve's budget scales with what costs: course length and, on a finer
mesh, the nodes (`OcpSettings.budget`)."""

from __future__ import annotations

import pytest

from itt_planner.ocp.course_settings import OcpSettings


@pytest.mark.parametrize("model", ["3d", "1d"])
def test_half_spacing_doubles_the_seconds_per_km(model: str) -> None:
    base = OcpSettings()
    half = OcpSettings(h_min_m=base.h_min_m / 2, h_max_m=base.h_max_m / 2,
                       h_max_1d_m=base.h_max_1d_m / 2)
    fixed = base.budget(model, 0.0)[1]
    per_km = base.budget(model, 10_000.0)[1] - fixed
    assert half.budget(model, 10_000.0)[1] - fixed == pytest.approx(2 * per_km)
    # the iterations do not scale with the nodes
    assert half.budget(model, 10_000.0)[0] == base.budget(model, 10_000.0)[0]


def test_coarser_and_uniform_meshes() -> None:
    base = OcpSettings()
    coarse = OcpSettings(h_max_m=2 * base.h_max_m, h_max_1d_m=2 * base.h_max_1d_m)
    assert coarse.budget("3d", 20_000.0) == base.budget("3d", 20_000.0)
    uniform = OcpSettings(uniform_m=1.0)
    assert uniform.budget("3d", 1000.0)[1] == pytest.approx(60.0 + 15.0 * base.h_max_m)


def test_explicit_budget_wins() -> None:
    fixed = OcpSettings(max_iter=7, max_cpu_time_s=3.0, h_max_m=0.5)
    assert fixed.budget("3d", 50_000.0) == (7, 3.0)
