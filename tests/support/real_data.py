"""Where the tests find real courses and rides, and which ones exist.

The three MIT-licensed rides travel with the repo in `tests/data/`; the unlicensed ones
live only in `../shared/data/` beside the checkout (CI has it, a user's clone does not).
`data_path` looks in the repo first, then beside it, and otherwise SKIPS the calling test
with a reason that names the file, so a clone alone runs green.
"""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
REPO_DATA = ROOT / "tests" / "data"
SHARED_DATA = ROOT.parent / "shared" / "data"

#: Every real file of the corpus, as its path under `../shared/data/`.
COURSES = ("courses/tokyo2020_olympic_itt_lap.csv",)
RIDES = ("rides/edge810_vector_stjohns_2013.fit", "rides/edge1000_ardennes_2019.fit",
         "rides/elemnt_shanghai_2019_stopgo.fit", "rides/sauerland_2025.fit",
         "rides/zwift_bologna_tt_virtual.tcx")


def locate(relpath: str) -> Path | None:
    """`tests/data/<file name>` if the repo ships it, else `../shared/data/<relpath>`, else None."""
    for path in (REPO_DATA / Path(relpath).name, SHARED_DATA / relpath):
        if path.is_file():
            return path
    return None


def data_path(relpath: str) -> Path:
    """The real file `relpath` (e.g. `rides/sauerland_2025.fit`), or skip the test."""
    path = locate(relpath)
    if path is None:
        pytest.skip(f"{Path(relpath).name}: real data without a licence to ship it; it lives "
                    f"only in ../shared/data/{relpath} beside the checkout (CI has it), "
                    f"not found at {SHARED_DATA / relpath}")
    return path
