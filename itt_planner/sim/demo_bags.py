"""Demo ride logs: a simulated ride of the virtual rider written as an MCAP ride log.

The rider follows the full-course plan with the simulator's lag and noise (the
`open_loop` policy of `simulate_ride`: no pacing engine in the loop, so the log is a plain
recording of a ride), on a truth that may differ from the plan's belief (a `Scenario`,
e.g. a critical power 5 % below the plan's), and the simulated sensors give GPS at 1 Hz
with 3 m of correlated noise, wheel speed and power with their own noise. Every log says
in its metadata that it is SIMULATED and how to remake it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from itt_planner.course.geometry import Course
from itt_planner.errors import IttError
from itt_planner.logs.ridelog_writer import RideLogWriter, RideMetadata
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import Rider
from itt_planner.ocp.plan import Plan
from itt_planner.sim.loop import simulate_ride
from itt_planner.sim.scenarios import Policy, Scenario

#: Stamp of the start of every demo ride (2026-05-09 12:00:00 UTC): a fixed, plausible
#: race-day clock, so that remaking a bag with the same seed gives the same bytes.
DEMO_START_POSIX_S = 1778328000.0


@dataclass(frozen=True)
class BagSummary:
    """What `make-bag` reports."""

    output: str
    course: str
    rider: str
    scenario: str
    seed: int
    messages: int
    ride_duration_s: float
    finish_time_s: float
    size_bytes: int

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def record_simulated_ride(course: Course, rider: Rider, plan: Plan, output: str | Path, *,
                          seed: int = 0, scenario: Scenario | str = Scenario.NOMINAL,
                          conditions: Conditions = Conditions()) -> BagSummary:
    """Simulate `rider` riding `plan` on `course` in `scenario` and write the sensors'
    log to `output`.

    Raises:
        IttError: the simulated rider did not reach the finish; an unknown scenario.
        RideLogError: the log cannot be written.
    """
    result = simulate_ride(course, rider, plan, policy=Policy.OPEN_LOOP, seed=seed,
                           scenario=scenario, conditions=conditions, t0_s=DEMO_START_POSIX_S)
    name = result.scenario.value
    if math.isnan(result.finish_time_s):  # ran out of time before the line
        msg = f"simulated {rider.name} did not finish {course.name}; no log written"
        raise IttError(msg)
    remake = (f"itt-planner make-bag --course {course.name} --rider {rider.name} "
              f"--seed {seed}{'' if name == 'nominal' else f' --scenario {name}'} "
              f"-o {Path(output).name}")
    metadata = RideMetadata(source=f"SIMULATED ride ({remake})", sha256=course.source_sha256,
                            device="itt-planner simulator (not a real device)", rider=rider.name)
    with RideLogWriter(output, metadata=metadata) as writer:
        for sample in result.samples:
            writer.write_sample(sample)
    stamps = [s.stamp_s for s in result.samples]
    return BagSummary(
        output=str(output), course=course.name, rider=rider.name, scenario=name, seed=seed,
        messages=len(result.samples), ride_duration_s=round(max(stamps) - min(stamps), 3),
        finish_time_s=round(float(result.finish_time_s), 3),
        size_bytes=Path(output).stat().st_size,
    )
