"""Benchmark of start-up: how long a fresh process takes to import what it runs.

Every process the project starts imports part of the package first: the CLI for each
command, the player and recorder beside the node, the course re-solve worker, Ray's sweep
workers. The packages load their public names on first use (`lazy_loader`, stubs in
`__init__.pyi`), so each imports what it uses. Each entry below is a fresh
`python -c "import ..."`, timed wall to wall, with the median of `--runs` runs; its
baseline, in the same run, imports every stage of the package first and then the same
(what that process cost when importing any module imported every stage).

Usage: .venv/bin/python -m bench.bench_startup [--runs 7]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: What each kind of process imports before its first line of work.
ENTRIES = {
    "cli (--help, any command's start)": "import itt_planner.cli",
    "play (cli + player)": "import itt_planner.cli, itt_planner_ros.player",
    "record (cli + recorder)": "import itt_planner.cli, itt_planner_ros.recorder",
    "re-solve worker": "import itt_planner.live.resolve_worker",
    "ride log reader": "import itt_planner.logs.ridelog",
    "pacing engine": "import itt_planner.live.engine",
}
#: Every stage at once: what any import cost when the packages' `__init__`s imported all.
EVERY_STAGE = ("import itt_planner.course.loader, itt_planner.live.engine, itt_planner.logs, "
               "itt_planner.ocp.course_problem; ")


def _median_s(code: str, runs: int) -> float:
    env_path = f"{ROOT}:{ROOT / 'ros_ws' / 'src' / 'itt_planner_ros'}"
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT,
                       env={"PYTHONPATH": env_path, "PATH": ""})
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()
    print(f"median of {args.runs} runs, s: what it imports / every stage first (baseline)")
    for name, code in ENTRIES.items():
        lazy, eager = _median_s(code, args.runs), _median_s(EVERY_STAGE + code, args.runs)
        print(f"{name:36s} {lazy:6.3f} / {eager:6.3f}  ({lazy / eager:.2f} x the baseline)")


if __name__ == "__main__":
    main()
