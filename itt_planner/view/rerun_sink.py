"""Where a Rerun ride recording goes: a `.rrd` file, a viewer, or the web viewer.

`RerunSink.parse` reads the CLI / node-parameter string; `open_recording` makes an
explicit `rr.RecordingStream` (never Rerun's global one, so a live node and an offline
review can record side by side) wired to that sink.

    file:PATH.rrd       save to a file (the review recording)
    spawn               start a native viewer and stream to it
    connect             stream to a running viewer (default gRPC URL)
    connect:URL         ... at `rerun+http://HOST:PORT/proxy`
    serve               host a gRPC server in this process and the web viewer next to it
    none                record nothing (every log call is a cheap no-op)
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal
from urllib.parse import quote

import rerun as rr

from itt_planner.errors import IttError

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


def open_recording(sinks: RerunSink | Sequence[RerunSink], *, app_id: str = "itt_planner",
                   recording_id: str | None = None) -> rr.RecordingStream:
    """A new recording stream tee'd to every sink. It carries no layout: the ride's is sent
    with its course (`rerun_scene.log_course`, the map zoomed to it). A default layout
    sent here as well was the one Rerun's web viewer showed from a saved file (the map at
    zoom 13 whatever the course).

    Several sinks serve the usual review-while-live case: watch the ride in a viewer
    (`spawn`, `connect`, `serve`) and keep the `.rrd` for afterwards (`file`), from one
    stream, so every log call is made once.

    Args:
        sinks: one destination or several (`none` sinks are ignored).
        app_id: Rerun application id (recordings of one app share blueprints in the viewer).
        recording_id: fix it to merge several processes' logs into one recording.

    Raises:
        IttError: a file cannot be created or the viewer cannot be spawned.
    """
    wanted = [sinks] if isinstance(sinks, RerunSink) else list(sinks)
    live = [s for s in wanted if s.kind != "none"]
    rec = rr.RecordingStream(app_id, recording_id=recording_id, default_enabled=bool(live))
    if not live:
        return rec
    targets: list[rr.FileSink | rr.GrpcSink | rr.GrpcServerSink] = []
    servers: list[tuple[RerunSink, rr.GrpcServerSink]] = []
    try:
        for sink in live:
            if sink.kind == "file":
                path = Path(sink.target)
                path.parent.mkdir(parents=True, exist_ok=True)
                targets.append(rr.FileSink(path))
            elif sink.kind == "spawn":
                rr.spawn(port=DEFAULT_GRPC_PORT, connect=False)
                targets.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{DEFAULT_GRPC_PORT}/proxy"))
            elif sink.kind == "connect":
                targets.append(rr.GrpcSink(sink.target or None))
            else:  # serve
                server = rr.GrpcServerSink(port=sink.grpc_port)
                servers.append((sink, server))
                targets.append(server)
        rec.set_sinks(*targets)
        for sink, server in servers:
            rr.serve_web_viewer(web_port=sink.web_port, open_browser=False, connect_to=server.uri)
            log.info("Rerun web viewer at %s (gRPC %s)", sink.web_viewer_url, server.uri)
    except (OSError, RuntimeError, ValueError) as err:
        names = ", ".join(str(s) for s in live)
        raise IttError(f"rerun sink {names}: {err}") from err
    return rec
