"""Typed errors of the core library.

Library code raises these with the file, topic, field or solver status in the message;
only the CLI turns them into messages and exit codes.
"""

from __future__ import annotations


class IttError(Exception):
    """Base class of every error the core raises on purpose."""


class CourseError(IttError):
    """A course or GPS track could not be read or is not usable (names the file)."""


class RiderError(IttError):
    """A rider preset or rider YAML file is invalid (names the field)."""


class SolveError(IttError):
    """An optimal control problem failed; carries the solver's return status."""

    def __init__(self, message: str, *, status: str) -> None:
        super().__init__(message)
        self.status = status


class RideLogError(IttError):
    """A ride file or MCAP ride log could not be read or written (names file/topic)."""
