"""Where a session's inputs and outputs go: the MCAP ride log, the Rerun recording and the
node's publishers, one method per kind of record.

Each sink is optional. The MCAP writer is not thread-safe (a node's inputs and its tick
run on different threads): every write holds one lock. Rerun's recorder locks itself.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

from itt_planner.live.advice import Advice, Diagnostic
from itt_planner.live.samples import Sample
from itt_planner.model.state import RiderState

if TYPE_CHECKING:
    from itt_planner.logs.ridelog import RawRecord
    from itt_planner.logs.ridelog_writer import RideLogWriter
    from itt_planner.ocp.plan import Plan
    from itt_planner.view.rerun_log import RideRecorder

#: What the node publishes: an advice, or a diagnostics batch with its stamp.
Publish = Callable[[Advice | None, list[Diagnostic] | None, float], None]


class Sinks:
    """The outputs of a session (module docstring).

    Args:
        writer: the MCAP ride log of inputs and outputs, or None.
        recorder: the Rerun recorder, or None.
        publish: called with each advice and each diagnostics batch, or None.
        plan_version: the version of the plan the recorder was built with.
    """

    def __init__(self, writer: RideLogWriter | None = None,
                 recorder: RideRecorder | None = None, publish: Publish | None = None,
                 plan_version: int = 0) -> None:
        self.writer = writer
        self.recorder = recorder
        self.publish = publish
        self._plan_version = plan_version
        self._io_lock = threading.Lock()

    def sample(self, sample: Sample, estimate: Callable[[], RiderState | None],
               raw: RawRecord | None = None) -> None:
        """An input sample (`estimate`: the state after it, which places it in Rerun;
        asked only when there is a recorder). `raw` is the sample's message as read from
        a log (copied byte for byte); without it the sample is encoded anew."""
        if self.recorder is not None:
            self.recorder.log_sample(sample, estimate())
        if self.writer is not None:
            with self._io_lock:
                if raw is not None:
                    self.writer.write_raw(raw)
                else:
                    self.writer.write_sample(sample)

    def raw(self, raw: RawRecord) -> None:
        """A log message that is no input sample (e.g. /clock), copied to the output log."""
        if self.writer is not None:
            with self._io_lock:
                self.writer.write_raw(raw)

    def advice(self, advice: Advice, plan: Plan, stamp_s: float) -> None:
        """An advice; `plan` is the plan in force (drawn anew when its version changed)."""
        if self.writer is not None:
            with self._io_lock:
                self.writer.write_advice(advice)
        if self.recorder is not None:
            if advice.plan_version != self._plan_version:  # a re-solved plan adopted
                self._plan_version = advice.plan_version
                self.recorder.log_plan(plan, advice.plan_version)
            self.recorder.log_state(advice.state)
            self.recorder.log_advice(advice)
        if self.publish is not None:
            self.publish(advice, None, stamp_s)

    def state(self, state: Callable[[], RiderState | None]) -> None:
        """The rider's state at a tick without advice (Rerun only: asked only when there
        is a recorder, as asking may predict the estimate forward)."""
        if self.recorder is not None and (now := state()) is not None:
            self.recorder.log_state(now)

    def diagnostics(self, diagnostics: list[Diagnostic], stamp_s: float) -> None:
        """A diagnostics batch."""
        if self.writer is not None:
            with self._io_lock:
                self.writer.write_diagnostics(diagnostics, stamp_s)
        if self.recorder is not None:
            self.recorder.log_diagnostics(diagnostics)
        if self.publish is not None:
            self.publish(None, diagnostics, stamp_s)

    def close(self) -> None:
        """Finish the output log and flush Rerun."""
        try:
            if self.writer is not None:
                with self._io_lock:
                    self.writer.close()
        finally:
            if self.recorder is not None:
                self.recorder.rec.flush(timeout_sec=10.0)
                self.recorder.rec.disconnect()
