"""The stage kernels are cached by the model's expressions, not by its name."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from itt_planner.model import dynamics
from itt_planner.model.dynamics import build_3d
from itt_planner.ocp.transcription import stage_kernels


def test_a_model_rebuilt_with_other_constants_gets_its_own_kernels(
        monkeypatch: pytest.MonkeyPatch) -> None:
    model = build_3d()
    kernels = stage_kernels(model, 1, compile_c=False)
    assert stage_kernels(build_3d(), 1, compile_c=False) is kernels  # same expressions
    monkeypatch.setattr(dynamics, "_EPS_AIR", 1.0)  # an experiment's smoother drag
    other = build_3d()
    assert other.ode.name() == model.ode.name()
    rebuilt = stage_kernels(other, 1, compile_c=False)
    assert rebuilt is not kernels
    # At one point (every input 0.5) the two integrators differ: the drag smoothing is in them.
    args = [ca.DM.ones(f.size1_in(i), f.size2_in(i)) * 0.5 for f in (kernels[0],)
            for i in range(f.n_in())]
    assert not np.allclose(np.asarray(kernels[0](*args)[0]), np.asarray(rebuilt[0](*args)[0]))
