"""Shared fixtures: real data (in the repo or beside the checkout), small synthetic courses."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from real_data import data_path


@pytest.fixture(scope="session")
def data_file() -> Callable[[str], Path]:
    """Look up a real file by its path under `../shared/data` (`"rides/x.fit"`):
    `tests/data/` first (the MIT rides the repo ships), then `../shared/data/`, else the
    test is skipped with a reason naming the file (unlicensed, lives only beside CI)."""
    return data_path
