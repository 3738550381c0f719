"""CasADi's OpenBLAS runs one thread unless the user says otherwise (`itt_planner`'s
package docstring: the Bologna 3D plan cost 82 s CPU with a thread per core, 49 s with
one, the same iterates)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

CODE = "import os, itt_planner; print(os.environ['OPENBLAS_NUM_THREADS'])"


@pytest.mark.parametrize(("given", "expected"), [(None, "1"), ("3", "3")])
def test_importing_the_package_sets_one_blas_thread_unless_set(given: str | None,
                                                               expected: str) -> None:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    out = subprocess.run([sys.executable, "-c", CODE], env=env, capture_output=True,
                         text=True, check=True)
    assert out.stdout.strip() == expected
