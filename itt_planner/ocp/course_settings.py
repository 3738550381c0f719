"""What a full-course solve is asked for: its settings (`OcpSettings`: mesh, boundary
conditions, objective weights, budget) and, for a re-solve from mid-course, where and
from which state it starts (`Start`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from itt_planner.model.wprime import WPrimeModel

#: The default coarsest mesh spacings (3D, 1D) the CPU budget per km is measured at.
_DEFAULT_H_MAX_M = 4.0
_DEFAULT_H_MAX_1D_M = 10.0


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
        window_min_m, window_m, window_overlap_m, window_corner_m: a cold 3D solve of a
            course longer than `window_min_m` first solves overlapping windows of about
            `window_m` of work each (its length plus `window_corner_m` per corner: the
            city gets shorter windows than the open road), each `window_overlap_m` into
            the next, and polishes their stitched point on the full mesh
            (`course_windows`; bench/RESULTS.md, 2026-12-02, helpers C and H3). A
            length, not a node count: the iterations grow with the course (the active
            arcs to form), not with the mesh (rovereto-like at half spacing, 17,133
            nodes: 187 iterations). 45 km: St John's (41.3 km) converges cold in 145
            iterations, the 57 km Ardennes ride needed 487, the 80 km Shanghai ride
            stopped at its budget after 571. 12 km and 150 m per corner (15 km by
            length alone before, each window from the coarse mesh first): Ardennes in 6
            windows instead of 4, 134 s CPU in the windows instead of 319 (the smaller
            windows converge cold from the 1D plan in 79-196 iterations where the 15 km
            ones took 232-331 after a coarse run that failed).
        window_arc_guess_corners_per_km: a window with more corner apices per km than
            this starts from the default (arc) guess instead of the 1D plan: the 1D
            plan's corner speeds (centre line) do not match the guess's line and lean.
            Shanghai's city windows (4.9-8.7 per km) took 244, 343, 154 and 221
            iterations from it, 468, 511, 173 and 334 from the 1D plan; on open road the
            1D plan was better (Ardennes 39-50 km, 2.0 per km, from the 1D plan's state:
            155 against 192).
        window_max_iter, window_min_iter, window_iter_factor: a window's first run stops
            at `window_iter_factor` times the iterations of the slowest window converged
            before it, at least `window_min_iter`, at most `window_max_iter` (the first
            window: `window_max_iter`), and starts again with the smaller bound push, as
            after an early failure (`course_windows.window_iter_cap`). Converging windows
            took 79-343 iterations (bench/RESULTS.md, 2026-12-02, helper H3), while the
            Ardennes ride's last window with the calibrated rider wandered for 1,063
            iterations (282 s) to `Restoration_Failed` and then converged in 124 with the
            smaller push. Measured with the calibrated riders (bench/RESULTS.md,
            2026-12-03, helper P): above 200 a window converged in at most 1.36x the
            iterations of the slowest one before it (Ardennes 338 after 248; below,
            Shanghai 146 after 77), while Shanghai's window 5 ran to the fixed cap of 600
            (104 s CPU) after windows of 37-77 and converged in 154 with the smaller push,
            and Sauerland's window 9 ran to 600 (156 s) after windows of 91-170 and
            converged in 109 with it.
        window_mu_max: the cap on the adaptive barrier of a window's runs from the 1D
            plan (IPOPT's `mu_max`, as the 1D model's own `solver._MU_MAX_1D`). The 1D
            plan rides the centre line's corners faster than the 3D model's grip
            (largest constraint violation 1.1-44 at the Ardennes windows' starts):
            uncapped, the barrier rose to 1e3-1e4 in 4 of those 6 windows while IPOPT
            restored feasibility, the point went deep into the bounds' interior (39-50
            km: objective 1644 s at the guess, 1732 s after 35 iterations) and the
            window crawled back to its optimum (1663 s) for ~170 iterations. Capped
            (bench/RESULTS.md, 2026-12-03, helper P4): Ardennes' windows 897
            iterations instead of 1,061, each to an objective no worse; whole plans
            Ardennes 1,237 iterations instead of 1,396, Shanghai 1,049 (1,231),
            Sauerland 1,352 (1,545). Not for the arc guess (dense corners): the same cap
            on cold 3D starts from the default guess was neutral (2026-12-01: 0.975x
            over 7 courses, 0.5x to 2.1x each).
        window_polish_tol: IPOPT's tolerance of the run on the full mesh resumed from
            the windows' stitched point (`tol` for every other run); its plan is
            verified as any. Near the optimum this run's adaptive barrier fell below
            1e-9 and a full step put a constraint 0.165 off, then restoration and 66-78
            iterations of ~1 s CPU each, still running (Ardennes, from the windows of
            two other settings, after reaching 7e-6 and 5.5e-6 of error; at 1e-5: 17
            iterations; bench/RESULTS.md, 2026-12-03, helper P4).
        never_monotone: the first run's adaptive barrier without its fall-back to the
            monotone mode (`solver.full_course_solver`); set for the 1D plan the windows
            start from, whose only use is a guess. The Ardennes ride's (calibrated rider)
            otherwise let the barrier fall to 1e-11 by iteration 10 and wandered: 254
            iterations instead of 323, the windows after it 1,140 in all instead of
            1,237 (the finish +0.003 %); Shanghai's and Sauerland's ran the same iterates
            either way (bench/RESULTS.md, 2026-12-03, sixth session). Not for every
            plan: over the convergence study's courses it was worse on some (Bologna 81
            -> 257 iterations, 2026-12-02), so elsewhere it is a restart only.
    """

    h_min_m: float = 1.0
    # Longer intervals make each shooting interval span up to ~1 s of the unstable roll
    # mode at climbing speeds; IPOPT then needed 1e14 regularisation and did not converge.
    h_max_m: float = _DEFAULT_H_MAX_M
    # The 1D model has no roll mode: coarser intervals are accurate and converge.
    h_max_1d_m: float = _DEFAULT_H_MAX_1D_M
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
    window_min_m: float = 45_000.0
    window_m: float = 12_000.0
    window_overlap_m: float = 2_000.0
    window_corner_m: float = 150.0
    window_arc_guess_corners_per_km: float = 4.0
    window_max_iter: int = 600
    window_min_iter: int = 200
    window_iter_factor: float = 1.5
    window_mu_max: float = 0.1
    window_polish_tol: float = 1e-5
    never_monotone: bool = False

    def budget(self, model: str, length_m: float) -> tuple[int, float]:
        """(iterations, seconds) for one solve of `length_m` metres with `model`.

        Iterations scale with the course: 3D 500 + 80 per km (the 17 km Bologna course
        needed ~500 with the old guess; 40 per km before: the 80 km Shanghai ride's
        windows, `window_min_m`, ran 2,566 iterations of 3,701, a hard window stopped
        at its iteration share twice with CPU left, bench/RESULTS.md, 2026-12-02, helper
        C; a window's iteration costs what its nodes cost, so the CPU seconds are the
        guard), 1D 600 + 40 per km (at double spacing the 1D
        first start on Bologna converged on a step artefact in 340 iterations and the
        re-solve on the refined mesh needed 487 more: 827 against 722 of 400 + 20 per
        km; 1D iterations are cheap, its CPU seconds are the guard). Seconds scale with what
        costs, the nodes: 3D 60 s + 15 s per km, 1D 20 s + 2 s per km at the default
        coarsest spacing (`h_max_m` 4 m, `h_max_1d_m` 10 m), times default / actual
        spacing (`uniform_m` if set) on a finer mesh. Why: the mesh has ~250-300 nodes
        per km at the default 3D spacing (bologna 4,309 for 16.1 km, stjohns 10,340 for 41.3 km);
        half the spacing doubles them (8,155 and 20,660) and the CPU time per
        iteration with them (stjohns 0.57 s at x2, 0.88 s at x1, 2.3 s at x0.5 on the
        shared machine), while the iterations stay of the same order. A coarser mesh
        keeps the default seconds: its iterations did not get proportionally cheaper
        (those figures; tokyo2020 needed 162 s CPU at x2). With seconds per
        km alone, bologna, verona-like, stjohns and tokyo2020 at half spacing stopped
        at the CPU budget (bench/RESULTS.md, 2026-12-01 and 2026-12-02). The seconds
        are CPU seconds of this process (IPOPT's `max_cpu_time`, and the restarts'
        share): on a loaded, shared machine wall time says more about the neighbours
        than about the course. 15 s per km (10 before): the 80 km Shanghai ride's
        windows (`window_min_m`) took ~130 s CPU per 15 km window at load ~7 and
        reached its fifth window of six after 650 of its 860 s (bench/RESULTS.md,
        2026-12-02, helper C); a converging solve never uses its whole budget, so only a
        failing one runs longer.
        """
        km = max(length_m, 0.0) / 1000.0
        if model == "3d":
            finer = max(1.0, _DEFAULT_H_MAX_M / (self.uniform_m or self.h_max_m))
            iters, secs = 500 + 80 * km, 60.0 + 15.0 * km * finer
        else:
            finer = max(1.0, _DEFAULT_H_MAX_1D_M / (self.uniform_m or self.h_max_1d_m))
            iters, secs = 600 + 40 * km, 20.0 + 2.0 * km * finer
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
