"""Shared fixtures: real data (in the repo or beside the checkout) and the courses fitted to
it, ROS 2 environments, and the hairpin course and plan (support.hairpin_fixtures)."""

from __future__ import annotations

import functools
import os
import random
from collections.abc import Callable
from pathlib import Path

import pytest
from support.real_data import data_path

from itt_msgs_py.dds_env import CONFLICTING_VARS, localhost_env, ros_unavailable_reason
from itt_planner.course.geometry import COURSE_SUFFIX, Course
from itt_planner.course.loader import load_course
from itt_planner.course.track_files import file_sha256

#: The hairpin course and its 3D plan (`course`, `plan`) for the closed-loop tests.
pytest_plugins = ["support.hairpin_fixtures"]

#: The test files that take longest (each up to a few minutes on 2 cores, much of it
#: waiting on real-time playback or on solves), longest first. `make test` hands whole
#: files to the xdist workers in collection order (`--dist loadfile
#: --no-loadscope-reorder`), so these are collected first: each worker starts a long one
#: and the short files fill in at the end. One started last ended the run minutes after
#: the rest. The ROS node's tests mostly wait, so the other worker solves meanwhile.
LONG_MODULES = (  # seconds each on 2 workers, 2026-12-02 (load ~1.5): 143, 69, 43, 23, ...
    "tests/ros/test_ros_node.py", "tests/sweep/test_sweep.py",
    "tests/live/test_advice_belief.py", "tests/ros/test_ros_play_record.py",
    "tests/ocp/test_ocp.py", "tests/live/test_engine.py",
    "tests/calibration/test_calibration.py", "tests/ocp/test_horizon.py",
    "tests/sim/test_simulate.py", "tests/live/test_estimate.py", "tests/logs/test_import.py",
    "tests/test_corpus.py", "tests/view/test_report.py", "tests/calibration/test_validate.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """`LONG_MODULES` first in their order, each module's tests in their own order."""
    rank = {module: k for k, module in enumerate(LONG_MODULES)}
    items.sort(key=lambda item: rank.get(item.nodeid.partition("::")[0], len(rank)))


@pytest.fixture(scope="session")
def data_file() -> Callable[[str], Path]:
    """Look up a real file by its path under `../shared/data` (`"rides/x.fit"`):
    `tests/data/` first (the MIT rides the repo ships), then `../shared/data/`, else the
    test is skipped with a reason naming the file (unlicensed, lives only beside CI)."""
    return data_path


@pytest.fixture(scope="session")
def real_course(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str], Course]:
    """The course fitted to a real file (`load_course`, default options), by its path under
    `../shared/data` (skips like `data_file`). Fitted once per run: saved as .course.npz
    where the xdist workers of this run share it (a 100 km ride takes seconds to fit)."""
    base = tmp_path_factory.getbasetemp()
    # Under xdist each worker has its own base inside the run's; never across runs.
    cache = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "real_courses"
    cache.mkdir(exist_ok=True)

    @functools.cache
    def fitted(relpath: str) -> Course:
        src = data_path(relpath)
        saved = cache / f"{src.name}-{file_sha256(src)[:16]}{COURSE_SUFFIX}"
        if saved.is_file():
            return Course.load(saved)
        partial = saved.with_name(f".{saved.name}.{os.getpid()}")
        load_course(src).save(partial)
        partial.replace(saved)  # atomic: another worker reads a whole file or none
        return Course.load(saved)  # the same object whoever fitted it

    return fitted


@pytest.fixture(scope="session")
def ros_unavailable() -> str | None:
    """None where real rclpy and the built `itt_msgs` import, else set-up's one-line reason."""
    return ros_unavailable_reason()


@pytest.fixture
def requires_ros(ros_unavailable: str | None) -> None:
    """Skips the test, with set-up's reason, where real ROS 2 is not installed or built."""
    if ros_unavailable is not None:
        pytest.skip(ros_unavailable)


@pytest.fixture
def ros_env(requires_ros: None,  # noqa: ARG001  (requested for its skip)
            monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """Loopback-only Fast DDS on a random ROS_DOMAIN_ID of this test's own, set in this
    process (for in-process rclpy) and returned as a full environment for subprocesses.

    Domains are split between xdist workers (d % workers == worker index) so two tests
    running at once never share one; within a worker the pick is random, so a process left
    over from an earlier test is unlikely to be on the same domain."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    index = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw"))
    domain = random.choice([d for d in range(1, 102) if d % workers == index % workers])
    for var in CONFLICTING_VARS:
        monkeypatch.delenv(var, raising=False)
    for var, value in localhost_env(domain).items():
        monkeypatch.setenv(var, value)
    # Child processes' prints reach pipes as they happen (tests wait for their lines).
    return {**os.environ, "PYTHONUNBUFFERED": "1"}
