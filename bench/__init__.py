"""Benchmarks: standalone scripts printing medians and ratios (`python -m bench [NAME ...]`).

Importing the package (`python -m bench.bench_x`, as `bench/__main__.py` runs each one)
puts `tests/` on `sys.path`, as pytest's `pythonpath` does, so benchmarks share the tests'
helpers as `support.*` (synthetic tracks and rides, real-data lookup).
"""

import sys
from pathlib import Path

_TESTS = str(Path(__file__).resolve().parents[1] / "tests")
if _TESTS not in sys.path:
    sys.path.insert(0, _TESTS)
