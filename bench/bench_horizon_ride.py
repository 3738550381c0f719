"""Benchmark of the receding horizon on a real ride: fallbacks, statuses, iterations, latency.

Replays a ride file (default: the Zwift Bologna ride of `../shared/data`, real power on
the route of a Giro ITT) through a pacing session on its own course, deterministic (the
iteration caps are the budget), and prints one JSON object: the advice and how many
were fallbacks, the horizon replans by solver status (`Suboptimal_Feasible` and
`Smoothed_Feasible` are usable unconverged iterates, counted apart), the replans that
failed per km of the course, iterations and wall-clock solve times (median, p95), the
advice figures of `advice_stats`, the real-time factor and the load average (a shared
machine: times are comparable only within one run). Where the wall went: the horizon
solves (`solve_time_total_s`), the waits for late re-solves of the course
(`resolve_wait_s`) and the rest (`rest_s`: reading the log, estimator, shaping); advice
held for a standing rider without a solve (`held_standing`, `live.horizon_step`) is
counted apart from the replans.

Course re-solves of the rest of the course are off by default (`--course-replan-period
0`): each waits for a full-course OCP in a worker process (a deterministic replay waits
for it), which held a replay for minutes on this ride. With `--course-replan-period 30`
(the session's default) the JSON's `course_replans` says how many were asked for,
adopted and failed (by solver status), which model each solved (`by_model`:
`--course-resolve-model`, `live.resolve_model`), and how many the engine held
(`live.resolve_gate`: backed off while the rider leaves each new plan at once, skipped
while the rider is stopped). `--plan` replays with a saved full-course plan
(the cache key hashes the OCP's code, so a change there would solve it again).

Usage: .venv/bin/python bench/bench_horizon_ride.py [--rider RIDER.yaml] (default:
       bench/bologna_rider.yaml) [--ride FILE.tcx] [--model 3d|1d] [--cache-dir DIR]
       [--stop-s SECONDS] [--course-replan-period 0] [--course-resolve-model auto|3d|1d-line]
       [--plan FILE.plan.npz]
       [--advice-out FILE.npz] (each advice's stamp, s, target power, cue, fallback)
       [--compare-to FILE.npz] (another run's `--advice-out`: the JSON's `advice_delta`
       gives the median and largest |difference| of the target power at the same stamps
       and how many differ by more than 10 W)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from itt_planner.live.advice import Advice  # noqa: E402
from itt_planner.live.advice_shaping import advice_stats  # noqa: E402
from itt_planner.live.engine import ON_PLAN  # noqa: E402
from itt_planner.live.horizon_step import HELD_STANDING  # noqa: E402
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed  # noqa: E402
from itt_planner.logs.ride_import import import_ride  # noqa: E402
from itt_planner.logs.ridelog import RideLogReader  # noqa: E402
from itt_planner.session.config import SessionConfig, build_engine  # noqa: E402
from itt_planner.session.ride_session import RideSession  # noqa: E402

DEFAULT_RIDE = ROOT.parent / "shared" / "data" / "rides" / "zwift_bologna_tt_virtual.tcx"
DEFAULT_RIDER = ROOT / "bench" / "bologna_rider.yaml"


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, math.ceil(q * len(ordered)) - 1)]


def advice_delta(advice: list[Advice], other: Path) -> dict[str, float | int]:
    """Target power of `advice` against another run's saved advice at the same stamps."""
    saved = np.load(other)
    mine = {round(a.stamp_s, 3): a.target_power_w for a in advice}
    theirs = dict(zip(np.round(saved["stamp_s"], 3), saved["target_power_w"], strict=True))
    common = sorted(set(mine) & set(theirs))
    delta = np.abs(np.array([mine[t] - theirs[t] for t in common]))
    return {"stamps_compared": len(common), "stamps_only_here": len(mine) - len(common),
            "stamps_only_there": len(theirs) - len(common),
            "median_abs_delta_w": float(np.median(delta)) if len(delta) else math.nan,
            "mean_abs_delta_w": float(np.mean(delta)) if len(delta) else math.nan,
            "max_abs_delta_w": float(np.max(delta)) if len(delta) else math.nan,
            "over_10_w": int(np.sum(delta > 10.0)), "identical": int(np.sum(delta == 0.0))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ride", type=Path, default=DEFAULT_RIDE)
    ap.add_argument("--rider", default=str(DEFAULT_RIDER), help="rider preset or YAML")
    ap.add_argument("--model", default="3d", help="full-course plan model")
    ap.add_argument("--cache-dir", default=".itt_cache")
    ap.add_argument("--stop-s", type=float, default=math.inf, help="replay this much only")
    ap.add_argument("--course-replan-period", type=float, default=0.0)
    ap.add_argument("--course-resolve-model", default="auto",
                    help="what a re-solve solves: auto, 3d, or 1d-line (live.resolve_model)")
    ap.add_argument("--plan", default="", help="a saved full-course plan (else the cache's)")
    ap.add_argument("--advice-out", type=Path, default=None, help="save the advice (npz)")
    ap.add_argument("--compare-to", type=Path, default=None, help="advice saved by another run")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "ride.mcap"
        import_ride(args.ride, log)
        config = SessionConfig(course=str(args.ride), rider=args.rider, model=args.model,
                               plan=args.plan, plan_cache=args.cache_dir, deterministic=True,
                               course_replan_period_s=args.course_replan_period,
                               course_resolve_model=args.course_resolve_model)
        engine = build_engine(config)
        session = RideSession(config, engine, keep_advice=True)
        first = last = None
        start = time.perf_counter()
        for raw, value in RideLogReader(log, namespace=config.namespace).decoded():
            stamp = raw.log_time_ns / 1e9
            first = stamp if first is None else first
            if stamp - first > args.stop_s:
                break
            session.advance_to(stamp)
            last = stamp
            if isinstance(value, GpsFix | WheelSpeed | PowerReading):
                session.on_sample(value, raw)
        session.finish()
        wall = time.perf_counter() - start
        advice = session.advice or []
        counts = session.counts()
        session.close()
    if args.advice_out is not None:
        np.savez(args.advice_out, stamp_s=[a.stamp_s for a in advice],
                 s_m=[a.state.s_m for a in advice],
                 target_power_w=[a.target_power_w for a in advice],
                 cue=[int(a.cue) for a in advice], fallback=[a.fallback for a in advice],
                 status=[a.solver_status for a in advice])
    # Advice from a replan carries its solver status and iterations (a fallback: the
    # failed one's); the plan's own advice says `on_plan`, advice held for a standing
    # rider without a solve `held_standing`.
    replans = [a for a in advice if a.solver_status not in (ON_PLAN, "finished", HELD_STANDING)]
    failed = [a for a in replans if a.fallback]
    times = engine.solve_times_s
    ride_s = (last - first) if first is not None and last is not None else 0.0
    print(json.dumps({
        "ride": args.ride.name, "rider": args.rider, "ride_s": ride_s,
        "advice": len(advice), "fallbacks": session.fallbacks,
        "fallback_pct": 100.0 * session.fallbacks / max(len(advice), 1),
        "replans": len(replans),
        "held_standing": sum(a.solver_status == HELD_STANDING for a in advice),
        "statuses": dict(Counter("FAILED" if a.fallback else a.solver_status for a in replans)),
        "failed_per_km": dict(Counter(int(a.state.s_m // 1000) for a in failed)),
        "iterations_median": statistics.median(a.iterations for a in replans) if replans else None,
        "iterations_p95": percentile([a.iterations for a in replans], 0.95) if replans else None,
        "solve_time_median_s": statistics.median(times) if times else None,
        "solve_time_p95_s": percentile(times, 0.95) if times else None,
        # Of the wall: the horizon solves, the waits for late re-solves of the course (a
        # deterministic replay adopts each `delay_s` of stamps after its request), the rest.
        "solve_time_total_s": sum(times), "resolve_wait_s": engine.plans.resolve_wait_s,
        "rest_s": wall - sum(times) - engine.plans.resolve_wait_s,
        "realtime_factor": ride_s / wall if wall > 0 else None, "wall_s": wall,
        "load_average": os.getloadavg(), "counts": counts,
        "course_replans": {
            "asked": counts.get("course_replans_asked", 0),
            "adopted": counts.get("course_replans_adopted", 0),
            "failed": counts.get("course_replan_failures", 0),
            # Held by `live.resolve_gate`: the rider left the last plans at once, or stopped.
            "backed_off": counts.get("course_replans_backed_off", 0),
            "skipped_stopped": counts.get("course_replans_skipped_stopped", 0),
            "backoffs": counts.get("course_replan_backoffs", 0),
            # Which model each re-solve solved (`live.resolve_model`), and the finish each
            # adopted plan predicted (for comparing the models on the same ride).
            "by_model": {k.removeprefix("course_replans_model_"): v
                         for k, v in counts.items() if k.startswith("course_replans_model_")},
            "line_refused": counts.get("course_replans_line_refused", 0),
            "line_after_3d_failed": counts.get("course_replans_line_after_3d_failed", 0),
            "adopted_plans": engine.plans.adopted,
            "failed_by_status": {k.removeprefix("course_replan_failed_"): v
                                 for k, v in counts.items()
                                 if k.startswith("course_replan_failed_")}},
        "advice_stats": advice_stats(advice) if advice else {},
        "advice_delta": advice_delta(advice, args.compare_to) if args.compare_to else None,
    }, default=str))


if __name__ == "__main__":
    main()
