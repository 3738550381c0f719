"""Plans solved once and kept on disk, keyed by everything they depend on.

The key hashes the course (source hash and the arrays themselves), the rider, the
conditions, the OCP settings, the model, and the source code of the modules that make a
plan (`PLAN_CODE_MODULES`: physics, transcription, mesh, bounds, solver, verification),
so neither a changed input nor a physics change can hit a stale plan. Only converged and
verified plans are stored. Writing goes through a temporary file and an atomic rename.

A stored plan keeps the primal-dual point of its NLP (`plan.POINT_ARRAYS`, in the same
file), so the first re-solve of the rest of the course from a cached
plan starts warm like the later ones (`live.course_replan`).
"""

from __future__ import annotations

import hashlib
import importlib
import inspect
import json
import logging
import os
from dataclasses import asdict, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from itt_planner.course.geometry import Course
from itt_planner.errors import IttError
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import Rider
from itt_planner.ocp.course_nlp import PrimalDual
from itt_planner.ocp.course_problem import solve_plan_point
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.plan import PLAN_SUFFIX, Plan

log = logging.getLogger(__name__)

#: Modules whose source decides what a plan is (hashed into every key): the physics, the
#: transcription, mesh, bounds and guess, the solver and its options, the full-course
#: problem's settings, NLP and restart strategies, the verification and the plan itself.
PLAN_CODE_MODULES = (
    "itt_planner.model.dynamics", "itt_planner.model.params", "itt_planner.model.steady",
    "itt_planner.model.wprime", "itt_planner.model.rider", "itt_planner.model.conditions",
    "itt_planner.ocp.transcription", "itt_planner.ocp.codegen", "itt_planner.ocp.mesh",
    "itt_planner.ocp.bounds",
    "itt_planner.ocp.guess", "itt_planner.ocp.solver", "itt_planner.ocp.course_settings",
    "itt_planner.ocp.course_nlp", "itt_planner.ocp.course_problem",
    "itt_planner.ocp.course_restarts", "itt_planner.ocp.course_refine",
    "itt_planner.ocp.course_budget",
    "itt_planner.ocp.course_windows", "itt_planner.ocp.verify",
    "itt_planner.ocp.plan",
)


@lru_cache(maxsize=1)
def code_hash() -> str:
    """Hex digest of the source of `PLAN_CODE_MODULES` (computed once per process)."""
    h = hashlib.sha256()
    for name in PLAN_CODE_MODULES:
        h.update(name.encode())
        h.update(inspect.getsource(importlib.import_module(name)).encode())
    return h.hexdigest()[:16]


def plan_key(course: Course, rider: Rider, conditions: Conditions, settings: OcpSettings,
             model: str) -> str:
    """Hex digest identifying one solve."""
    h = hashlib.sha256()
    h.update(course.source_sha256.encode())
    for name in ("s_m", "x_m", "y_m", "z_m", "theta_rad", "kappa_per_m", "beta_rad",
                 "width_left_m", "width_right_m"):
        h.update(getattr(course, name).tobytes())
    meta = {"rider": asdict(rider), "conditions": asdict(conditions),
            "settings": asdict(settings), "model": model, "code": code_hash()}
    h.update(json.dumps(meta, sort_keys=True, default=str).encode())
    return h.hexdigest()[:24]


def with_point(plan: Plan, point: PrimalDual | None) -> Plan:
    """`plan` keeping `point` (`plan.POINT_ARRAYS`) if it is the point of the plan's own
    NLP (on the plan's nodes), else `plan` as it is."""
    if point is None or not np.array_equal(point.nodes, plan.s_m):
        return plan
    return replace(plan, point_w=point.w, point_lam_x=point.lam_x, point_lam_g=point.lam_g)


def solve_keeping_point(course: Course, rider: Rider, conditions: Conditions,
                        settings: OcpSettings, model: str) -> Plan:
    """`course_problem.solve_plan`, the plan keeping its primal-dual point if it
    converged (`with_point`; what a plan saved for `--plan` should be solved with)."""
    return with_point(*solve_plan_point(course, rider, conditions, settings, model=model))


def load_or_solve(course: Course, rider: Rider, conditions: Conditions = Conditions(),
                  settings: OcpSettings = OcpSettings(), model: str = "3d",
                  cache_dir: Path = Path(".itt_cache")) -> Plan:
    """The cached plan for these inputs, or solve, store and return it.

    Only converged and verified plans are stored (`Plan.converged`), so a capped,
    failed or invalid solve is retried next time; a cached file that is not converged
    (written by other code) is ignored. A solved plan keeps its primal-dual point
    (`solve_keeping_point`); a cached file from before that loads without it.

    Raises:
        SolveError: unusable input (see `course_problem.solve_plan`).
    """
    key = plan_key(course, rider, conditions, settings, model)
    path = Path(cache_dir) / f"{course.name}_{model}_{key}{PLAN_SUFFIX}"
    if path.exists():
        try:
            cached = Plan.load(path)
        except IttError as err:
            log.warning("ignoring unreadable cached plan %s: %s", path, err)
        else:
            if cached.converged:
                return cached
            log.warning("ignoring cached plan %s: status %s", path, cached.status)
    plan = solve_keeping_point(course, rider, conditions, settings, model)
    if plan.converged and plan.meta.get("success"):
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
        plan.save(tmp)
        tmp.replace(path)
    return plan
