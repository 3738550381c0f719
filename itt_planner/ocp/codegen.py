"""Compile CasADi Functions to a shared library once per machine, and load them back.

The OCP's per-interval kernels (integrator, its Jacobian, the stage Hessian) are a few
tens of thousands of scalar operations each and are called thousands of times per NLP
iteration. Compiled C (gcc -O1) runs them ~10x faster than CasADi's SX virtual machine,
but compiling takes tens of seconds, so the library is cached on disk under a name that
is the hash of its C source: any change of the model gives a new file, an unchanged
model is never compiled twice. Without a working C compiler the Functions are returned
as they are (interpreted), with a logged warning.
"""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca

log = logging.getLogger(__name__)

#: Optimisation level: -O1 compiles a ~50k-operation Hessian in seconds; -O2/-O3 take
#: several times longer for a few percent (measured in bench/RESULTS.md).
_CFLAGS = ("-O1", "-fPIC", "-shared")


def cache_dir() -> Path:
    """`$ITT_PLANNER_CACHE`, else `$XDG_CACHE_HOME/itt_planner`, else ~/.cache/itt_planner."""
    env = os.environ.get("ITT_PLANNER_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "itt_planner"


def compiled(name: str, functions: list[ca.Function]) -> list[ca.Function]:
    """The same Functions, evaluated by compiled C code from a cached shared library."""
    compiler = shutil.which(os.environ.get("CC", "gcc"))
    if compiler is None:
        log.warning("no C compiler found: CasADi kernels %s run interpreted (slower)", name)
        return functions
    with tempfile.TemporaryDirectory() as tmp:
        gen = ca.CodeGenerator(f"{name}.c")
        for fun in functions:
            gen.add(fun)
        gen.generate(tmp + os.sep)
        source = Path(tmp, f"{name}.c").read_bytes()
    digest = hashlib.sha256(source + " ".join(_CFLAGS).encode()).hexdigest()[:16]
    lib = cache_dir() / f"{name}_{digest}.so"
    if not lib.exists():
        lib.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=lib.parent) as tmp:
            src = Path(tmp, f"{name}.c")
            src.write_bytes(source)
            out = Path(tmp, lib.name)
            log.info("compiling CasADi kernels %s (once per machine)", name)
            done = subprocess.run([compiler, *_CFLAGS, str(src), "-o", str(out), "-lm"],
                                  capture_output=True, text=True, check=False)
            if done.returncode != 0:
                log.warning("compiling %s failed, kernels run interpreted: %s", name,
                            done.stderr[-500:])
                return functions
            out.replace(lib)  # atomic: concurrent processes never load a partial file
    return [ca.external(fun.name(), str(lib)) for fun in functions]
