# Copyright 2026 itt-planner team
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""The signals of the package's processes (the node, `play`, `record`): SIGINT and
SIGTERM only set a stop event, so that each stops in order and finishes its files (the
node also kills its re-solve worker: `pacing_node.run`); `STACKS_SIGNAL` writes every
thread's Python stack to stderr and the process runs on, which is how a hung process
says where it hangs (the ROS tests send it before they kill one)."""

from __future__ import annotations

import faulthandler
import signal
import threading
from typing import Any

#: Every thread's stack to stderr (module docstring).
STACKS_SIGNAL = signal.SIGUSR1


def handle_signals(stop: threading.Event) -> dict[int, Any]:
    """Set `stop` on SIGINT and SIGTERM, stacks on `STACKS_SIGNAL` (module docstring).
    Only the main thread can install handlers: on another thread nothing is installed
    and the caller stops its own way. Returns the SIGINT/SIGTERM handlers replaced."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    faulthandler.register(STACKS_SIGNAL, all_threads=True)
    return {sig: signal.signal(sig, lambda _sig, _frame: stop.set())
            for sig in (signal.SIGINT, signal.SIGTERM)}
