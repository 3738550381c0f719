"""Overlapping windows for the 3D solve of a long course: where they go, what each one
starts from and must leave, and how their primal-dual points are stitched into one
point of the full-course NLP (`course_restarts`, "windows first").

Why: a cold 3D solve forms the active arcs (C11 on the inside edges, C15, C16, W' = 0)
a node or two per iteration over the whole course at once, so its iterations grow with
the course while each costs more per node: the 80 km Shanghai ride (245 corners) stopped
at its CPU budget after 571 iterations, the 98.8 km Sauerland ride ran for more than 7
minutes without an end (bench/RESULTS.md, 2026-12-02). A window of ~15 km is a course
of the size the 3D model converges on in 100-300 iterations (Bologna, verona-like,
tokyo2020), so the cost grows with the course's length, not with its square. Measured
(bench/RESULTS.md, 2026-12-02, helper C), converged and verified: Shanghai 2,080-2,566
iterations, 679-764 s CPU (its city-centre window alone up to 1,161 iterations: windows
are cut by length, not by corners); Sauerland 1,210-1,245, 343-399 s; Ardennes 942, 250 s
(cold: 487 iterations, 390 s wall).

The windows split the course (from the full mesh's nodes, so that every window's nodes
are nodes of the full mesh) into cores of equal work (`plan_windows`: length plus a
length per corner, cut away from apices); window k spans its core and `overlap_m` of
the next one, starts from window k-1's state at its core's start (all states: the
stitched point is continuous there) and must leave at its end the W' the course's 1D
plan has there (`e_final_min`): the 1D plan allocates W' over the whole course, which a
window alone cannot see. The overlap absorbs the end of a window, where it spends what
the bound leaves and rides to a free end speed. The stitched point (each window's core,
its multipliers too) is then polished on the full mesh by a run resumed from it
(`Budget.run(resume=)`), which frees the W' allocation and the junctions.

Why by work, not by length (bench/RESULTS.md, 2026-12-02, helper H3): a window's
iterations grow with its corners (Shanghai's 15 km city window 556 where the open-road
ones took 166-210), and each costs what its nodes cost, so a shorter window where the
corners are dense costs less in all. With `OcpSettings` 12 km of work and 150 m per
corner (Ardennes 6 windows of 9-12 km, Shanghai 10 of 5-12 km), each window cold from
the 1D plan (from the default guess among dense corners,
`OcpSettings.window_arc_guess_corners_per_km`), no coarse mesh first: Ardennes 187 s
CPU (883 iterations) instead of 373 s (1,468), Shanghai 428 s (2,374) instead of 764 s
(2,080), Sauerland 318 s instead of 343 s, all converged and verified, finish within
+0.02 %. Shanghai's city windows still take 154-343 iterations each: 91 s CPU per 17 km
there, above the 60 s of issue 14.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from itt_planner.ocp.course_settings import OcpSettings, Start
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus, SolveResult
from itt_planner.ocp.transcription import Layout

#: How far a cut between windows stays from a corner's apex (or halfway between two
#: apices closer than twice this): a window then starts and ends on a straight, where
#: the fixed start state and the free end disturb no corner.
_CORNER_CLEAR_M = 250.0


@dataclass(frozen=True)
class Window:
    """One window: full-mesh node indices `[first, last]` it solves, and `core_end`,
    the node where the next window takes over (the last node for the last window)."""

    first: int
    core_end: int
    last: int


def plan_windows(nodes: np.ndarray, window_m: float, overlap_m: float,
                 corners_s_m: np.ndarray | None = None, corner_m: float = 0.0) -> list[Window]:
    """Windows over `nodes` (module docstring): cores of equal work, each window its core
    plus `overlap_m` of the course after it. The work of a stretch is its length plus
    `corner_m` per corner apex in it (`corners_s_m`), so a window holds about `window_m`
    of work: a stretch of city corners gets shorter windows than open road. A cut is kept
    `_CORNER_CLEAR_M` from the nearest apices (halfway between two closer ones)."""
    apex = np.sort(np.asarray([] if corners_s_m is None else corners_s_m, float))
    apex = apex[(apex > nodes[0]) & (apex < nodes[-1])]
    work = (nodes - nodes[0]) + corner_m * np.searchsorted(apex, nodes, side="right")
    n = max(1, math.ceil(float(work[-1]) / window_m - 1e-9))
    cut_s = np.interp(work[-1] * np.arange(1, n) / n, work, nodes)
    if len(apex):  # at least `_CORNER_CLEAR_M` from the apices either side (or halfway)
        nxt = np.searchsorted(apex, cut_s)
        prev_s = np.where(nxt > 0, apex[np.clip(nxt - 1, 0, None)], -np.inf)
        next_s = np.where(nxt < len(apex), apex[np.clip(nxt, None, len(apex) - 1)], np.inf)
        clear = np.minimum(0.5 * (next_s - prev_s), _CORNER_CLEAR_M)
        cut_s = np.clip(cut_s, prev_s + clear, next_s - clear)
    cuts = np.unique(np.concatenate([[0], np.searchsorted(nodes, cut_s), [len(nodes) - 1]]))
    ends = np.searchsorted(nodes, nodes[cuts[1:]] + overlap_m)
    return [Window(int(a), int(b), int(min(e, len(nodes) - 1)))
            for a, b, e in zip(cuts[:-1], cuts[1:], ends, strict=True)]


def window_corners_per_km(nodes: np.ndarray, corners_s_m: np.ndarray) -> float:
    """Corner apices per km of the window spanning `nodes`."""
    inside = np.count_nonzero((corners_s_m >= nodes[0]) & (corners_s_m <= nodes[-1]))
    return 1000.0 * inside / max(float(nodes[-1] - nodes[0]), 1.0)


def window_iter_cap(settings: OcpSettings, converged_iters: list[int]) -> int:
    """Iterations a window's first run may take before it starts again with the smaller
    bound push (`OcpSettings.window_max_iter`, why there): `window_iter_factor` times the
    iterations of the slowest window converged before it (`converged_iters`), within
    `window_min_iter` and `window_max_iter`; the first window `window_max_iter`."""
    if not converged_iters:
        return settings.window_max_iter
    cap = math.ceil(settings.window_iter_factor * max(converged_iters))
    return int(min(settings.window_max_iter, max(settings.window_min_iter, cap)))


def window_start(states: tuple[str, ...], layout: Layout, prev: SolveResult, node: int,
                 s_m: float) -> Start:
    """The state of the previous window's run (on `layout`) at its node `node`, which
    is at `s_m`: where the next window starts, every state fixed."""
    x, _, _ = layout.split(prev.w)
    return Start(s_m, {name: float(x[i, node]) for i, name in enumerate(states)})


def end_reserve(base: Plan, s_m: float, w_prime_j: float, final_min: float,
                last: bool) -> float:
    """The W' (fraction, E_n) a window must leave at its end `s_m`: the 1D plan's there,
    the course's own `e_final_min` for the last window."""
    if last:
        return final_min
    return float(np.clip(base.at("w_prime_j", s_m) / w_prime_j, 0.0, 1.0))


def plan_between(plan: Plan, a_m: float, b_m: float) -> Plan:
    """`plan` from `a_m` to `b_m` (its nodes between them and both ends, every per-node
    array interpolated there): a window's guess, which must span the window's mesh."""
    s = plan.s_m
    new_s = np.concatenate([[a_m], s[(s > a_m) & (s < b_m)], [b_m]])
    arrays = {f.name: np.interp(new_s, s, value) for f in dataclasses.fields(plan)
              if isinstance(value := getattr(plan, f.name), np.ndarray) and value.shape == s.shape}
    return dataclasses.replace(plan, **arrays)


def stitch(layout: Layout, windows: list[Window], runs: list[SolveResult]) -> SolveResult:
    """The windows' primal-dual points joined into one point of the full-course NLP
    (`layout`, no slacks): window k gives the intervals of its core and the nodes after
    its first up to its core's end (the first window its first node too), so that each
    junction node comes from the window it is inside of, not from the next one, where it
    is the fixed start. Returned as a resumable run (`SolveResult`)."""
    nx, n_path = layout.nx, layout.n_path
    x_all = np.empty((nx, layout.n_nodes))
    u_all = np.empty((layout.nu, layout.n_intervals))
    lx_all, lu_all = np.empty_like(x_all), np.empty_like(u_all)
    gaps = np.empty((layout.n_intervals, nx))
    path = np.empty((layout.n_nodes, n_path))
    accel = np.empty(layout.n_intervals if layout.accel else 0)
    for k, (win, run) in enumerate(zip(windows, runs, strict=True)):
        if run.lam_x is None or run.lam_g is None:
            raise ValueError("stitch: a window's run has no multipliers (not converged)")
        lay = Layout(nx, layout.nu, 0, win.last - win.first, n_path, layout.accel)
        x, u, _ = lay.split(run.w)
        lx, lu, _ = lay.split(run.lam_x)
        ints = slice(win.first, win.core_end)
        n_int = win.core_end - win.first
        lo = 0 if k == 0 else 1  # local index of the first node taken
        nodes = slice(win.first + lo, win.core_end + 1)
        x_all[:, nodes], lx_all[:, nodes] = x[:, lo: n_int + 1], lx[:, lo: n_int + 1]
        u_all[:, ints], lu_all[:, ints] = u[:, :n_int], lu[:, :n_int]
        g = run.lam_g
        gaps[ints] = g[: lay.n_gap].reshape(lay.n_intervals, nx)[:n_int]
        wpath = g[lay.n_gap: lay.n_gap + n_path * lay.n_nodes].reshape(lay.n_nodes, n_path)
        path[nodes] = wpath[lo: n_int + 1]
        if layout.accel:
            accel[ints] = g[lay.accel_rows][:n_int]
    lam_g = np.concatenate([gaps.ravel(), path.ravel(), accel])
    return SolveResult(layout.join(x_all, u_all), layout.join(lx_all, lu_all), lam_g,
                       float("nan"), PlanStatus.CONVERGED, "stitched", 0, 0.0)
