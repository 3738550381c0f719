"""What a simulated ride varies: how the truth differs from the planner's belief
(`Scenario`, `ScenarioSettings`) and what the rider follows (`Policy`)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


# (str, Enum), not StrEnum: str() and format() of the members stay as they were.
class Scenario(str, Enum):  # noqa: UP042
    """How the truth differs from the planner's belief (issue 4, item 5)."""

    NOMINAL = "nominal"
    CP_OVERESTIMATED = "cp-overestimated"
    HEADWIND = "headwind"
    HOT_START = "hot-start"


class Policy(str, Enum):  # noqa: UP042
    """What the simulated rider follows."""

    REPLANNED = "replanned"  # the pacing engine's advice, replanned in the loop
    OPEN_LOOP = "open_loop"  # the full-course plan, blindly
    EVEN_CP = "even_cp"  # constant critical power (the plan's line and corner speeds)


@dataclass(frozen=True)
class ScenarioSettings:
    """Magnitudes of the scenarios.

    Attributes:
        cp_factor: true CP / believed CP in `cp-overestimated`.
        headwind_mps: unforecast head wind over the second half in `headwind`.
        hot_start_m: how far the rider ignores advice in `hot-start` (clipped to a third
            of the course so short test courses keep a part to recover on) ...
        hot_start_factor: ... riding this factor times the plan's power.
    """

    cp_factor: float = 0.95
    headwind_mps: float = 3.0
    hot_start_m: float = 2000.0
    hot_start_factor: float = 1.15
