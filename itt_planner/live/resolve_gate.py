"""When the engine may ask for a re-solve of the rest of the course: not while the rider
is stopped, and less often while the rider does not follow the re-solved plans.

The engine asks for a re-solve (`course_replan`) whenever the rider is off the plan in
force, at most every `CourseReplanSettings.period_s`. A rider who rides their own power
rather than the advice leaves every new plan's W' band again soon after it is adopted:
on the Zwift Bologna ride (the ride's own power replayed) every ~30 s up the climb, 30
re-solves in 32 min, each 4-12 s of a worker's CPU (bench/RESULTS.md, 2026-12-01 and
2026-12-02). Such re-solves do not change what the rider does; the horizon replans
from the rider every second anyway. So:

- back-off: when the rider leaves a newly adopted plan's band within
  `backoff_within_s` of its adoption, the least interval between two requests doubles
  (up to `backoff_max_s`); once the rider keeps to an adopted plan for
  `backoff_within_s`, or the CP in use is refitted (a new belief), it is `period_s`
  again;
- stopped: a rider at or below the OCP's launch speed (`course_nlp.start_speed`: at a
  pause, or rolling off) is re-solved from once per stop (`_SAME_STOP_M`), at once (no
  back-off), and not again until the rider rides. Once, not never: the horizon cannot
  plan a standing start against a plan that passes there at speed (with no re-solve at
  the Bologna ride's 220 s pause, 82 replans there failed; bench/RESULTS.md,
  2026-12-02); the re-solved plan starts from the standstill. Again and again, every
  period while the rider stands (5 times on that ride, 19-48 s each), it only re-counts
  the W' the stop gives back: the horizon plans from the measured W' meanwhile.

Nothing is hidden: every request the plain period would have made and the gate held is
counted, `course_replans_backed_off` or `course_replans_skipped_stopped` (one per
`period_s` at most, as requests are), and every plan left within `backoff_within_s`
of its adoption `course_replan_backoffs`; the engine's counters (replay JSON `counts`)
and the session's warnings carry them.

Not thread-safe: the engine calls it with its solve lock held.
"""

from __future__ import annotations

import math
from collections import Counter

from itt_planner.live.course_replan import CourseReplanSettings

#: A stopped rider within this of the last re-solve from a stop is at the same stop (the
#: estimate drifts a few metres while standing).
_SAME_STOP_M = 50.0


class ResolveGate:
    """The back-off and the stopped-rider rule of the module docstring.

    Args:
        settings: the re-solve settings (period and back-off).
        launch_mps: the OCP's launch speed; at or below it the rider counts as stopped.
        stats: the engine's counters.
    """

    def __init__(self, settings: CourseReplanSettings, launch_mps: float,
                 stats: Counter[str]) -> None:
        self.settings = settings
        self.launch_mps = launch_mps
        self._stats = stats
        #: The least interval between two requests now (`period_s`, or backed off).
        self.interval_s = settings.period_s
        self._last_asked_s = -math.inf
        #: The last request asked or held (held ones counted once per period).
        self._last_counted_s = -math.inf
        #: Stamp of the last adoption whose following is not yet judged.
        self._adopted_s: float | None = None
        #: Where the last re-solve from a stopped rider was asked (None: riding since).
        self._stop_s_m: float | None = None
        #: Where the rider stood at the last `allow` (None: riding).
        self._standing_s_m: float | None = None

    def allow(self, stamp_s: float, speed_mps: float, s_m: float, remaining_m: float) -> bool:
        """Whether the engine may ask now (the rider is off the plan, at `s_m`). A request
        the plain period would make and the gate holds is counted (module docstring)."""
        st = self.settings
        stopped = not speed_mps > self.launch_mps
        self._standing_s_m = s_m if stopped else None
        if not stopped:
            self._stop_s_m = None
        since = stamp_s - self._last_asked_s
        if st.period_s <= 0 or remaining_m < st.min_remaining_m or since < st.period_s:
            return True  # the replanner's own rules decide (nothing is held here)
        if stopped:
            if self._stop_s_m is None or abs(s_m - self._stop_s_m) > _SAME_STOP_M:
                return True  # a new stop
        elif since >= self.interval_s:
            return True
        if stamp_s - self._last_counted_s >= st.period_s:
            self._last_counted_s = stamp_s
            self._stats["course_replans_skipped_stopped" if stopped
                        else "course_replans_backed_off"] += 1
        return False

    def asked(self, stamp_s: float) -> None:
        """A re-solve was asked for at `stamp_s` (after `allow`)."""
        self._last_asked_s = self._last_counted_s = stamp_s
        if self._standing_s_m is not None:
            self._stop_s_m = self._standing_s_m

    def adopted(self, stamp_s: float) -> None:
        """A re-solved plan was adopted at `stamp_s`: the rider's following is judged
        from here (`on_plan`, `off_plan`)."""
        self._adopted_s = stamp_s

    def on_plan(self, stamp_s: float) -> None:
        """The rider is inside the band of the plan in force at `stamp_s`: kept to an
        adopted plan for `backoff_within_s`, the interval is `period_s` again."""
        adopted = self._adopted_s
        if adopted is not None and stamp_s - adopted >= self.settings.backoff_within_s:
            self._adopted_s = None
            self.interval_s = self.settings.period_s

    def off_plan(self, stamp_s: float) -> None:
        """The rider is off the plan in force at `stamp_s`: off a plan adopted less than
        `backoff_within_s` ago, the interval doubles; later, it is `period_s` again."""
        adopted = self._adopted_s
        if adopted is None:
            return
        self._adopted_s = None
        st = self.settings
        if stamp_s - adopted < st.backoff_within_s:
            self.interval_s = min(2.0 * self.interval_s, max(st.backoff_max_s, st.period_s))
            self._stats["course_replan_backoffs"] += 1
        else:
            self.interval_s = st.period_s

    def reset(self) -> None:
        """A new belief (CP refitted): the interval is `period_s` again."""
        self._adopted_s = None
        self.interval_s = self.settings.period_s
