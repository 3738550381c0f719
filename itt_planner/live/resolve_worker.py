"""The process that re-solves the rest of the course for `course_replan.CourseReplanner`,
and the frames its jobs and replies travel in over the worker's stdin and stdout.

Why a process kept for all re-solves, and not `multiprocessing`:
`CourseReplanner._solve_in_worker`. A job is the tuple `CourseReplanner.request` builds
(what `resolve_model.solve_rest` takes); a reply is ("ok", (plan, point)) or
("error", status, message) for a solve that raised (the worker goes on).
"""

from __future__ import annotations

import os
import pickle
import signal
import sys
import threading
import time
from pathlib import Path
from typing import IO, Any

from itt_planner.errors import SolveError
from itt_planner.live.resolve_model import LineCache, solve_rest

#: Where the owner imported this package from: first on the worker's path. `python -c`
#: puts its working directory first, so a worker started in another checkout of the
#: project ran that checkout's solver (the replay benchmarks from a worktree ran
#: the main tree's re-solves: bench/RESULTS.md, 2026-12-03, fourth session).
PACKAGE_ROOT = str(Path(__file__).resolve().parents[2])
#: The worker's program (`python -c`). Not `python -m` this module: the package imports
#: it first, and runpy would run it a second time as `__main__` (a warning on stderr).
WORKER_PROGRAM = (f"import sys; sys.path.insert(0, {PACKAGE_ROOT!r}); "
                  f"from {__name__} import worker_main; worker_main(int(sys.argv[1]))")


def send(pipe: IO[bytes], obj: object) -> None:
    """One frame: the pickle's length (8 bytes, big-endian), then the pickle."""
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    pipe.write(len(data).to_bytes(8, "big") + data)
    pipe.flush()


def receive(pipe: IO[bytes]) -> Any:
    """The next frame's object, None at the end of the stream (the other side closed)."""
    head = pipe.read(8)
    if len(head) < 8:
        return None
    size = int.from_bytes(head, "big")
    data = pipe.read(size)
    if len(data) < size:
        return None
    return pickle.loads(data)


def _watch_owner(owner_pid: int) -> None:
    """Exit within a second of the owner's death (a killed node would otherwise leave
    the worker solving on, holding the node's stderr)."""
    while os.getppid() == owner_pid:
        time.sleep(1.0)
    os._exit(1)


def worker_main(owner_pid: int) -> None:
    """The worker process: pickled jobs on stdin, one reply per job on stdout (the plan
    and its point, or the error a solve raised: the worker goes on), until stdin ends.
    It ignores SIGINT (Ctrl-C reaches the whole process group; the owner kills it)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_watch_owner, args=(owner_pid,), daemon=True).start()
    # The replies get the stdout pipe to themselves: anything the solver's C code prints
    # goes to stderr instead.
    replies = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    lines = LineCache()
    while (job := receive(sys.stdin.buffer)) is not None:
        model, course, rider, conditions, settings, guess, start, warm, line_n, free = job
        try:
            reply: tuple[Any, ...] = ("ok", solve_rest(
                model, course, rider, conditions, settings, guess, start, warm, line_n, free,
                lines))
        except Exception as err:  # noqa: BLE001  (reported: the owner raises it from `take`)
            status = err.status if isinstance(err, SolveError) else "worker_exception"
            reply = ("error", status, f"{type(err).__name__}: {err}")
        send(replies, reply)
