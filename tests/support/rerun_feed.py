"""Feed engine-like events to a `RideRecorder`, as the replay and the node do."""

from __future__ import annotations

from itt_planner.live.advice import Advice, Diagnostic
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.model.state import RiderState
from itt_planner.view.rerun_log import RideRecorder

Event = GpsFix | WheelSpeed | PowerReading | RiderState | Advice | list[Diagnostic]


def record(recorder: RideRecorder, events: list[Event]) -> None:
    """Feed engine-like events to the recorder, as the replay and the node do (samples
    through `log_sample`, without the state after them)."""
    for ev in events:
        if isinstance(ev, RiderState):
            recorder.log_state(ev)
        elif isinstance(ev, Advice):
            recorder.log_advice(ev)
        elif isinstance(ev, list):
            recorder.log_diagnostics(ev)
        else:
            recorder.log_sample(ev)
