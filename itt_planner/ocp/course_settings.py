"""What a full-course solve is asked for: its settings (`OcpSettings`: mesh, boundary
conditions, objective weights, budget) and, for a re-solve from mid-course, where and
from which state it starts (`Start`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from itt_planner.model.wprime import WPrimeModel


@dataclass(frozen=True)
class OcpSettings:
    """Mesh, boundary and solver settings of the full-course OCP.

    Attributes:
        h_min_m, h_max_m: finest and coarsest mesh intervals (3D).
        h_max_1d_m: coarsest mesh interval of the 1D model.
        uniform_m: if set, a uniform mesh of this spacing instead (for mesh studies).
        margin_m: distance kept from each road edge (half the bike width + safety), C11.
        start_speed_mps: speed at the start line (raised for low grip, see module doc).
        e_final_min: lower bound on E_n at the finish (C12).
        w_delta, w_power: objective weights w_1, w_2 (model.md section 5).
        wprime_model: E9 variant.
        max_iter, max_cpu_time_s: the solver's budget for the whole solve (all
            restarts together); None (default) scales it with the course length
            (`budget`).
        tol: IPOPT's convergence tolerance.
        jit: compile the stage kernels to C with the machine's compiler (cached).
        verify: replay every plan (`verify.verify_plan`); off only for benchmarks of
            the solver alone.
    """

    h_min_m: float = 1.0
    # Longer intervals make each shooting interval span up to ~1 s of the unstable roll
    # mode at climbing speeds; IPOPT then needed 1e14 regularisation and did not converge.
    h_max_m: float = 4.0
    # The 1D model has no roll mode: coarser intervals are accurate and converge.
    h_max_1d_m: float = 10.0
    uniform_m: float | None = None
    margin_m: float = 0.5
    start_speed_mps: float = 1.0
    e_final_min: float = 0.0
    w_delta: float = 0.01
    w_power: float = 0.01
    wprime_model: WPrimeModel = WPrimeModel.SKIBA
    max_iter: int | None = None
    max_cpu_time_s: float | None = None
    tol: float = 1e-6
    jit: bool = True
    verify: bool = True

    def budget(self, model: str, length_m: float) -> tuple[int, float]:
        """(iterations, seconds) for one solve of `length_m` metres with `model`.

        Scaled with the course: 3D 500 iterations + 40 per km and 60 s + 10 s per km
        (the 17 km Bologna course needed ~500 iterations; measured times in
        bench/RESULTS.md), 1D 400 + 20 per km and 20 s + 2 s per km. The seconds are
        CPU seconds of this process (IPOPT's `max_cpu_time`, and the restarts' share):
        on a loaded, shared machine wall time says more about the neighbours than about
        the course.
        """
        km = max(length_m, 0.0) / 1000.0
        if model == "3d":
            iters, secs = 500 + 40 * km, 60.0 + 10.0 * km
        else:
            iters, secs = 400 + 20 * km, 20.0 + 2.0 * km
        return (int(self.max_iter if self.max_iter is not None else iters),
                float(self.max_cpu_time_s if self.max_cpu_time_s is not None else secs))


@dataclass(frozen=True)
class Start:
    """A solve from mid-course: the rest of the course from `s_m`, from a rider's state.

    Attributes:
        s_m: where the solve starts (the plan's `s_m[0]`; its `t_s` counts from there).
        state: model state name (`STATES_3D`) -> value at `s_m`; a state not given
            keeps its launch value (model.md section 5), a state the model does not
            have is ignored. Values outside the simple bounds (a rider measured off the
            road) are clipped into them.
    """

    s_m: float
    state: Mapping[str, float]
