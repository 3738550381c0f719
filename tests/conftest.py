"""Shared fixtures: real data (in the repo or beside the checkout), small synthetic courses."""

from __future__ import annotations

import os
import random
from collections.abc import Callable
from pathlib import Path

import pytest
from support.real_data import data_path

from itt_msgs_py.dds_env import CONFLICTING_VARS, localhost_env, ros_unavailable_reason

#: The hairpin course and its 3D plan (`course`, `plan`) for the closed-loop tests.
pytest_plugins = ["support.hairpin_fixtures"]


@pytest.fixture(scope="session")
def data_file() -> Callable[[str], Path]:
    """Look up a real file by its path under `../shared/data` (`"rides/x.fit"`):
    `tests/data/` first (the MIT rides the repo ships), then `../shared/data/`, else the
    test is skipped with a reason naming the file (unlicensed, lives only beside CI)."""
    return data_path


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
