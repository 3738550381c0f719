"""A sweep spec expanded into cases: one fully resolved solve each, keyed by a hash of its inputs.

The driver loads every course and rider once (files are read here, on the machine that
runs the sweep, so worker nodes need no copy of them) and builds each case's `Rider`,
`Conditions` and `OcpSettings`. A case's key hashes everything its result depends on:
`plan_cache.plan_key` (course arrays and source hash, rider, conditions, settings,
model) plus the labels and the split spacing it is recorded under, so a resumed sweep
recognises a case it has already solved and a changed input is a new case.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
from dataclasses import dataclass

from itt_planner.course.geometry import Course
from itt_planner.course.loader import load_course
from itt_planner.errors import IttError
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import Rider, load_rider
from itt_planner.ocp.cache import plan_key
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.sweep.spec import Equipment, SweepSpec, SweepSpecError


@dataclass(frozen=True)
class Case:
    """One solve of a sweep.

    Attributes:
        key: hash of every input (module docstring).
        course, rider_label: labels as in the spec (course: the spec's entry).
        course_key: which loaded course (`course_digest`).
        rider, equipment: the rider as loaded and the equipment choice; the worker applies
            one to the other, so a choice that makes the rider invalid is a failed case.
    """

    key: str
    course: str
    course_key: str
    rider_label: str
    rider: Rider
    equipment: Equipment
    conditions: Conditions
    settings: OcpSettings
    model: str
    split_every_m: float


def course_digest(course: Course) -> str:
    """Hash of a course's arrays and source (the course part of `plan_key`)."""
    return plan_key(course, Rider(), Conditions(), OcpSettings(), "")


def load_inputs(spec: SweepSpec) -> tuple[dict[str, Course], dict[str, Rider]]:
    """Every course and rider the spec names, loaded once.

    Raises:
        SweepSpecError: a course or rider that cannot be loaded (names it and why).
    """
    courses, riders = {}, {}
    for name in spec.courses:
        try:
            courses[name] = load_course(name)
        except IttError as err:
            raise SweepSpecError(f"courses: {name}: {err}") from None
    for name in spec.riders:
        try:
            riders[name] = load_rider(name)
        except IttError as err:
            raise SweepSpecError(f"riders: {name}: {err}") from None
    return courses, riders


def expand(spec: SweepSpec, courses: dict[str, Course], riders: dict[str, Rider]) -> list[Case]:
    """The spec's cases, duplicates across listed subsets dropped.

    Cases are ordered by course, model and W' model, so consecutive cases on one worker
    reuse the NLP it built (ocp's per-process solver cache).
    """
    digests = {name: course_digest(c) for name, c in courses.items()}
    cases: dict[str, Case] = {}
    for grid in spec.grids:
        for (course, rider_name, model, wind, wind_from, mu, wprime,
             equip) in itertools.product(grid.courses, grid.riders, grid.models,
                                         grid.wind_speeds_mps, grid.wind_from_rad, grid.mu,
                                         grid.wprime_models, grid.equipment):
            equipment = spec.equipment_named(equip)
            conditions = Conditions(mu_x=mu, mu_y=mu, wind_speed_mps=wind,
                                    wind_from_rad=wind_from)
            settings = dataclasses.replace(spec.settings, wprime_model=wprime)
            h = hashlib.sha256(plan_key(courses[course], riders[rider_name], conditions,
                                        settings, model).encode())
            h.update(f"{course}|{rider_name}|{equipment!r}|{spec.split_every_m!r}".encode())
            key = h.hexdigest()[:24]
            cases.setdefault(key, Case(key, course, digests[course], rider_name,
                                       riders[rider_name], equipment, conditions, settings,
                                       model, spec.split_every_m))
    return sorted(cases.values(), key=lambda c: (c.course, c.model,
                                                 c.settings.wprime_model.value))
