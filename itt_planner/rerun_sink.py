"""Where a Rerun ride recording goes: a `.rrd` file, a viewer, or the web viewer.

`RerunSink.parse` reads the CLI / node-parameter string; `open_recording` makes an
explicit `rr.RecordingStream` (never Rerun's global one, so a live node and an offline
review can record side by side) wired to that sink, with the default blueprint.

    file:PATH.rrd       save to a file (the review recording)
    spawn               start a native viewer and stream to it
    connect             stream to a running viewer (default gRPC URL)
    connect:URL         ... at `rerun+http://HOST:PORT/proxy`
    serve               host a gRPC server in this process and the web viewer next to it
    none                record nothing (every log call is a cheap no-op)
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Literal
from urllib.parse import quote

import rerun as rr

from itt_planner.errors import IttError
from itt_planner.rerun_blueprint import default_blueprint

log = logging.getLogger(__name__)

SinkKind = Literal["file", "spawn", "connect", "serve", "none"]
_KINDS: tuple[SinkKind, ...] = ("file", "spawn", "connect", "serve", "none")
DEFAULT_WEB_PORT = 9090
#: Rerun's own default gRPC port (the native viewer listens here too).
DEFAULT_GRPC_PORT = 9876


@dataclass(frozen=True)
class RerunSink:
    """One Rerun destination.

    Attributes:
        kind: file | spawn | connect | serve | none.
        target: the `.rrd` path (file) or the gRPC URL (connect); "" otherwise.
        web_port: HTTP port of the web viewer (serve only).
        grpc_port: port of the in-process gRPC server (serve only).
    """

    kind: SinkKind
    target: str = ""
    web_port: int = DEFAULT_WEB_PORT
    grpc_port: int = DEFAULT_GRPC_PORT

    @classmethod
    def parse(cls, text: str) -> RerunSink:
        """Parse "file:PATH.rrd" | "spawn" | "connect[:URL]" | "serve" | "none".

        Raises:
            IttError: unknown kind, or a file sink without a path.
        """
        kind, _, rest = text.strip().partition(":")
        if kind not in _KINDS:
            msg = (f"rerun sink {text!r}: expected file:PATH.rrd, spawn, connect[:URL], "
                   f"serve or none")
            raise IttError(msg)
        if kind == "file" and not rest:
            raise IttError(f"rerun sink {text!r}: file sink needs a path (file:ride.rrd)")
        if kind in ("spawn", "serve", "none") and rest:
            raise IttError(f"rerun sink {text!r}: {kind} takes no argument")
        return cls(kind=kind, target=rest)

    def __str__(self) -> str:
        return f"{self.kind}:{self.target}" if self.target else self.kind

    @property
    def web_viewer_url(self) -> str:
        """The page to open for a `serve` sink (the web viewer, pointed at our gRPC server)."""
        grpc = f"rerun+http://127.0.0.1:{self.grpc_port}/proxy"
        return f"http://localhost:{self.web_port}/?url={quote(grpc, safe='')}"

    @property
    def keeps_process_alive(self) -> bool:
        """True when the data lives in this process (serve): the caller must not exit."""
        return self.kind == "serve"


def open_recording(sink: RerunSink, *, app_id: str = "itt_planner",
                   recording_id: str | None = None) -> rr.RecordingStream:
    """A new recording stream connected to `sink`, carrying the default blueprint.

    Args:
        sink: the destination.
        app_id: Rerun application id (recordings of one app share blueprints in the viewer).
        recording_id: fix it to merge several processes' logs into one recording.

    Raises:
        IttError: the file cannot be created or the viewer cannot be spawned.
    """
    rec = rr.RecordingStream(app_id, recording_id=recording_id,
                             default_enabled=sink.kind != "none")
    blueprint = default_blueprint()
    try:
        if sink.kind == "file":
            path = Path(sink.target)
            path.parent.mkdir(parents=True, exist_ok=True)
            rec.save(path, default_blueprint=blueprint)
        elif sink.kind == "spawn":
            rec.spawn(default_blueprint=blueprint)
        elif sink.kind == "connect":
            rec.connect_grpc(sink.target or None, default_blueprint=blueprint)
        elif sink.kind == "serve":
            uri = rec.serve_grpc(grpc_port=sink.grpc_port, default_blueprint=blueprint)
            rr.serve_web_viewer(web_port=sink.web_port, open_browser=False, connect_to=uri)
            log.info("Rerun web viewer at %s (gRPC %s)", sink.web_viewer_url, uri)
    except (OSError, RuntimeError, ValueError) as err:
        raise IttError(f"rerun sink {sink}: {err}") from err
    return rec
