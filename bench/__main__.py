"""Run every benchmark in bench/ one after the other: `python -m bench [NAME ...]`.

Each `bench_*.py` is a standalone script printing its own medians and ratios; they run
in separate processes (as `python -m bench.bench_x`, so the package puts `tests/` on the
path) so one benchmark's memory peak does not colour the next.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def main(names: list[str]) -> int:
    here = Path(__file__).resolve().parent
    scripts = sorted(here.glob("bench_*.py"))
    if names:
        scripts = [p for p in scripts if any(n in p.stem for n in names)]
    failed = 0
    for script in scripts:
        print(f"=== {script.name}", flush=True)
        failed += subprocess.call([sys.executable, "-m", f"bench.{script.stem}"],
                                  cwd=here.parent) != 0
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
