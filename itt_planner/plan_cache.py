"""Plans solved once and kept on disk, keyed by everything they depend on.

The key hashes the course (source hash and the arrays themselves), the rider, the
conditions, the OCP settings and the model, so a changed input can never hit a stale
plan. Writing goes through a temporary file and an atomic rename.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from dataclasses import asdict
from pathlib import Path

from itt_planner.conditions import Conditions
from itt_planner.course import Course
from itt_planner.errors import IttError
from itt_planner.ocp import OcpSettings, solve_plan
from itt_planner.plan import PLAN_SUFFIX, Plan
from itt_planner.rider import Rider

log = logging.getLogger(__name__)


def plan_key(course: Course, rider: Rider, conditions: Conditions, settings: OcpSettings,
             model: str) -> str:
    """Hex digest identifying one solve."""
    h = hashlib.sha256()
    h.update(course.source_sha256.encode())
    for name in ("s_m", "x_m", "y_m", "z_m", "theta_rad", "kappa_per_m", "beta_rad",
                 "width_left_m", "width_right_m"):
        h.update(getattr(course, name).tobytes())
    meta = {"rider": asdict(rider), "conditions": asdict(conditions),
            "settings": asdict(settings), "model": model}
    h.update(json.dumps(meta, sort_keys=True, default=str).encode())
    return h.hexdigest()[:24]


def load_or_solve(course: Course, rider: Rider, conditions: Conditions = Conditions(),
                  settings: OcpSettings = OcpSettings(), model: str = "3d",
                  cache_dir: Path = Path(".itt_cache")) -> Plan:
    """The cached plan for these inputs, or solve, store and return it.

    Only successful solves are stored, so a capped or failed solve is retried next time.

    Raises:
        SolveError: unusable input (see `ocp.solve_plan`).
    """
    path = Path(cache_dir) / f"{course.name}_{model}_{plan_key(course, rider, conditions, settings, model)}{PLAN_SUFFIX}"
    if path.exists():
        try:
            return Plan.load(path)
        except IttError as err:
            log.warning("ignoring unreadable cached plan %s: %s", path, err)
    plan = solve_plan(course, rider, conditions, settings, model=model)
    if plan.meta.get("success"):
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
        plan.save(tmp)
        os.replace(tmp, path)
    return plan
