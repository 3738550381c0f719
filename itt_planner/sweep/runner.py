"""Running a sweep: the cases not yet recorded go to Ray actors, rows to the store as they finish.

`run_sweep(spec, output, address=None, workers=None)`: loads the courses and riders once,
expands the cases, skips the ones the result dataset already holds (so an interrupted
sweep resumes where it stopped), and hands the rest to `workers` `CaseSolver` actors
(default: one per CPU of the cluster), two cases in flight per actor so none waits for
the driver. Finished rows are buffered and written as a part every `batch_size` cases
or `flush_s` seconds, and on the way out of an interrupt (Ctrl-C): only cases still in
flight then are lost and solved on the next run. A worker process that dies fails its
case (status "failed", the reason says so); Ray restarts the actor and the sweep goes
on. A tqdm bar on stderr shows cases done, failed and the ETA.
"""

from __future__ import annotations

import logging
import sys
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm

from itt_planner.sweep.cases import Case, expand, load_inputs
from itt_planner.sweep.cluster import ray_session
from itt_planner.sweep.solve import CONVERGED, FAILED, NOT_CONVERGED, CaseSolver, failed_row
from itt_planner.sweep.spec import SweepSpec
from itt_planner.sweep.store import ResultStore

log = logging.getLogger(__name__)

#: Cases queued per actor beyond the one it is solving (hides the driver round trip).
_IN_FLIGHT_PER_WORKER = 2


@dataclass(frozen=True)
class SweepSummary:
    """What one run of a sweep did. `counts` is by status of the cases solved in this run."""

    output: str
    cases: int
    already_done: int
    solved: int
    counts: dict[str, int]
    workers: int
    nodes: dict[str, int] = field(default_factory=dict)
    address: str = ""
    wall_s: float = 0.0

    @property
    def cases_per_min(self) -> float:
        return 60.0 * self.solved / self.wall_s if self.wall_s > 0 else 0.0


def run_sweep(spec: SweepSpec, output: str | Path, *, address: str | None = None,
              workers: int | None = None, retry_failed: bool = False, batch_size: int = 8,
              flush_s: float = 5.0, progress: bool = False,
              on_row: Callable[[dict[str, Any]], None] | None = None) -> SweepSummary:
    """Run the cases of `spec` not yet in `output` (module docstring).

    `retry_failed`: also re-run cases recorded as failed or not converged (their new row
    replaces the old one when the table is read). `on_row` is called with each row as it
    is recorded (after it is buffered for writing).

    Raises:
        SweepSpecError: a course or rider cannot be loaded.
        RayClusterError: Ray could not be started or joined.
        ResultStoreError: the result dataset cannot be read or written.
    """
    store = ResultStore(output)
    courses, riders = load_inputs(spec)
    cases = expand(spec, courses, riders)
    done = store.recorded(statuses=(CONVERGED,) if retry_failed else None)
    todo = [c for c in cases if c.key not in done]
    already = len(cases) - len(todo)
    log.info("sweep %s: %d cases, %d already recorded, %d to solve", spec.name, len(cases),
             already, len(todo))
    if not todo:
        return SweepSummary(str(store.path), len(cases), already, 0, {}, 0)
    t0 = time.perf_counter()
    with ray_session(address, workers) as session:
        # An actor holds one CPU for its life: more actors than CPUs would never start.
        n_workers = max(1, min(workers or session.cpus, session.cpus, len(todo)))
        if workers and workers > n_workers:
            log.warning("sweep %s: %d workers asked, %d used (%d CPUs, %d cases)", spec.name,
                        workers, n_workers, session.cpus, len(todo))
        rows = _dispatch(spec, todo, courses, n_workers, store, batch_size, flush_s,
                         progress, on_row)
        address_used = session.address
    store.compact()
    counts = Counter(r["status"] for r in rows)
    nodes = Counter(r.get("node_id") or "?" for r in rows)
    summary = SweepSummary(str(store.path), len(cases), already, len(rows),
                           {s: counts.get(s, 0) for s in (CONVERGED, NOT_CONVERGED, FAILED)},
                           n_workers, dict(nodes), address_used, time.perf_counter() - t0)
    if summary.counts[FAILED] or summary.counts[NOT_CONVERGED]:
        log.warning("sweep %s: %d case(s) failed and %d did not converge (see status/reason "
                    "in %s)", spec.name, summary.counts[FAILED], summary.counts[NOT_CONVERGED],
                    store.path)
    return summary


def _dispatch(spec: SweepSpec, todo: list[Case], courses: dict[str, Any], n_workers: int,
              store: ResultStore, batch_size: int, flush_s: float, progress: bool,
              on_row: Callable[[dict[str, Any]], None] | None) -> list[dict[str, Any]]:
    """Feed the actors, collect rows, write parts; returns the rows of this run."""
    import ray  # noqa: PLC0415

    # Restart a worker that dies (max_restarts) but never re-run its case by itself
    # (max_task_retries=0): a case that kills its worker would kill it again.
    actor_cls = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=0)(CaseSolver)
    actors: list[Any] = [actor_cls.remote() for _ in range(n_workers)]
    refs = {c.course_key: ray.put(courses[c.course]) for c in todo}
    queue = deque(todo)
    pending: dict[Any, tuple[Case, Any]] = {}
    rows: list[dict[str, Any]] = []
    buffer: list[dict[str, Any]] = []
    last_flush = time.monotonic()

    def submit(actor: Any) -> None:
        case = queue.popleft()
        pending[actor.solve.remote(case, [refs[case.course_key]])] = (case, actor)

    bar = tqdm(total=len(todo), desc=f"sweep {spec.name}", unit="case", file=sys.stderr,
               disable=not progress, dynamic_ncols=True)
    failed = 0
    try:
        for actor in actors * _IN_FLIGHT_PER_WORKER:
            if queue:
                submit(actor)
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=flush_s)
            for ref in ready:
                case, actor = pending.pop(ref)
                row = _row(ray, ref, case)
                row["sweep"] = spec.name
                rows.append(row)
                buffer.append(row)
                failed += row["status"] != CONVERGED
                bar.update(1)
                bar.set_postfix(failed=failed, refresh=False)
                if on_row is not None:
                    on_row(row)
                if queue:
                    submit(actor)
            if len(buffer) >= batch_size or time.monotonic() - last_flush >= flush_s:
                store.append(buffer)
                buffer.clear()
                last_flush = time.monotonic()
    finally:
        # Also on Ctrl-C: keep every finished case, then stop the workers.
        store.append(buffer)
        bar.close()
        for actor in actors:
            ray.kill(actor)
    return rows


def _row(ray: Any, ref: Any, case: Case) -> dict[str, Any]:
    """The row a worker returned, or a failed row if the worker died on this case."""
    try:
        row: dict[str, Any] = ray.get(ref)
        return row
    except (ray.exceptions.RayActorError, ray.exceptions.WorkerCrashedError) as err:
        # Its other queued case fails with it (max_task_retries=0); --retry-failed re-runs both.
        reason = f"the worker died while this case was queued or solving ({type(err).__name__})"
    except ray.exceptions.RayTaskError as err:
        first_line = str(err).splitlines()[0] if str(err) else type(err).__name__
        reason = f"error in the worker: {first_line}"
    log.warning("sweep case %s: %s", case.key, reason)
    return failed_row(case, reason)
