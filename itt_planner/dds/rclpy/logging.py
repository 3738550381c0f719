"""`rclpy.logging`: node loggers on top of the standard `logging` module."""

from __future__ import annotations

import logging as _logging
import threading
import time
from typing import Any


class RcutilsLogger:
    """A logger with rclpy's call shape (`warning(msg, throttle_duration_sec=..., once=...)`)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._log = _logging.getLogger(name)
        self._lock = threading.Lock()
        self._last: dict[tuple[int, str], float] = {}

    def get_child(self, name: str) -> RcutilsLogger:
        """Logger `self.name.name`."""
        return RcutilsLogger(f"{self.name}.{name}")

    def _emit(self, level: int, msg: str, *, throttle_duration_sec: float | None = None,
              once: bool = False, **_ignored: Any) -> bool:
        if throttle_duration_sec is not None or once:
            key = (level, msg if once else f"{_caller_key()}")
            now = time.monotonic()
            with self._lock:
                last = self._last.get(key)
                if last is not None and (once or now - last < (throttle_duration_sec or 0.0)):
                    return False
                self._last[key] = now
        self._log.log(level, msg)
        return True

    def debug(self, msg: str, **kwargs: Any) -> bool:
        """Log at DEBUG."""
        return self._emit(_logging.DEBUG, msg, **kwargs)

    def info(self, msg: str, **kwargs: Any) -> bool:
        """Log at INFO."""
        return self._emit(_logging.INFO, msg, **kwargs)

    def warning(self, msg: str, **kwargs: Any) -> bool:
        """Log at WARNING."""
        return self._emit(_logging.WARNING, msg, **kwargs)

    warn = warning

    def error(self, msg: str, **kwargs: Any) -> bool:
        """Log at ERROR."""
        return self._emit(_logging.ERROR, msg, **kwargs)

    def fatal(self, msg: str, **kwargs: Any) -> bool:
        """Log at CRITICAL."""
        return self._emit(_logging.CRITICAL, msg, **kwargs)


def _caller_key() -> str:
    """File and line of the log call: throttling is per call site, as in rclpy."""
    import sys

    frame = sys._getframe(3)
    return f"{frame.f_code.co_filename}:{frame.f_lineno}"


def get_logger(name: str) -> RcutilsLogger:
    """The logger `name`."""
    return RcutilsLogger(name)
