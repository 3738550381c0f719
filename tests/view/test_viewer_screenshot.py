"""Serve a ride recording to Rerun's web viewer and screenshot it with headless Chromium.

Marked `screenshot` (excluded by default): it installs Debian's `chromium` if missing and
takes ~70 s (ITT_SCREENSHOT_WAIT_S, default 60: the software-rendered viewer ingests ~4 MB
slowly). All traffic stays on loopback: Chromium's resolver maps every other host to
NOTFOUND (so the map view draws without tiles). Set ITT_SCREENSHOT_OUT=path.png to keep
the image (cropped to the viewer). By default the recording is a synthetic ride logged
in-process; ITT_SCREENSHOT_RRD=ride.rrd serves a saved recording instead, compacted first
(`rerun rrd optimize`: the viewer ingests a few large chunks much faster than thousands
of small ones) and served by the `rerun` CLI. bench/rerun_viewer.png in the README is a
full replay of the demo ride (`make demo`'s, with solve times measured), made so:

    .venv/bin/itt-planner replay bags/typical_verona-like_cp-overestimated.mcap \
        --course verona-like --rider typical --rrd /tmp/review.rrd --live-timing
    ITT_SCREENSHOT_RRD=/tmp/review.rrd ITT_SCREENSHOT_WAIT_S=100 \
        ITT_SCREENSHOT_OUT=bench/rerun_viewer.png .venv/bin/python -m pytest \
        tests/view/test_viewer_screenshot.py -m screenshot
"""

from __future__ import annotations

import http.server
import os
import shutil
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import rerun_cli
from PIL import Image, ImageOps
from support.rerun_feed import record
from support.synthetic_ride import RIDER, make_plan, make_ride

from itt_planner.course.loader import load_course
from itt_planner.view.rerun_log import RideRecorder
from itt_planner.view.rerun_sink import RerunSink, open_recording

pytestmark = pytest.mark.screenshot

#: Real seconds the page's load event is held back while the wasm viewer starts and draws.
VIEWER_LOAD_S = float(os.environ.get("ITT_SCREENSHOT_WAIT_S", "60"))
WINDOW = (1600, 1000)
ORANGE = np.array([255, 140, 0])


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _chromium() -> str:
    path = shutil.which("chromium")
    if path is None:
        subprocess.run(["apt-get", "update"], check=True, capture_output=True)
        subprocess.run(["apt-get", "install", "-y", "chromium"], check=True, capture_output=True)
        path = shutil.which("chromium")
    assert path, "apt-get install chromium did not provide a chromium binary"
    return path


def _wrapper_server(viewer_url: str, delay_s: float) -> http.server.ThreadingHTTPServer:
    """A page that shows the viewer in a full-window iframe and holds its load event.

    `chromium --screenshot` shoots at the load event, long before the wasm viewer has
    fetched the recording; a hidden image that takes `delay_s` to arrive delays it.
    (`--virtual-time-budget` does not help: it skips timers, not wasm compilation.)
    """
    page = (f'<html><body style="margin:0"><iframe src="{viewer_url}" '
            f'style="border:0;width:100vw;height:100vh"></iframe>'
            f'<img src="/hold" style="display:none"></body></html>').encode()

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            body = page
            if self.path == "/hold":
                time.sleep(delay_s)
                body = b""
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


@pytest.fixture
def viewer_url(tmp_path: Path) -> Iterator[str]:
    """The web viewer's page, showing ITT_SCREENSHOT_RRD or else a synthetic ride."""
    sink = RerunSink(kind="serve", web_port=_free_port(), grpc_port=_free_port())
    if rrd := os.environ.get("ITT_SCREENSHOT_RRD"):
        yield from _serve_file(Path(rrd), sink, tmp_path)
    else:
        yield from _serve_synthetic(sink)


def _serve_synthetic(sink: RerunSink) -> Iterator[str]:
    rec = open_recording(sink)
    # The demo course: ~21 min of synthetic ride (plan and samples from synthetic_ride).
    course = load_course("verona-like")
    plan = make_plan(course)
    recorder = RideRecorder(rec, course, RIDER, plan)
    recorder.log_course()
    record(recorder, make_ride(course, plan, rate_hz=2.0))
    rec.flush()
    yield sink.web_viewer_url
    rec.disconnect()


def _serve_file(rrd: Path, sink: RerunSink, tmp_path: Path) -> Iterator[str]:
    # The binary itself, not the `rerun` wrapper script: terminate() must reach the server.
    binary = str(Path(rerun_cli.__file__).parent / "rerun")
    compact = tmp_path / "compact.rrd"
    subprocess.run([binary, "rrd", "optimize", str(rrd), "-o", str(compact)], check=True,
                   capture_output=True)
    server = subprocess.Popen(
        [binary, str(compact), "--serve-web", "--bind", "127.0.0.1", "--port",
         str(sink.grpc_port), "--web-viewer-port", str(sink.web_port)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                socket.create_connection(("127.0.0.1", sink.web_port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "rerun --serve-web did not start"
                time.sleep(0.2)
        yield sink.web_viewer_url
    finally:
        server.terminate()
        server.wait(timeout=10)


def test_web_viewer_screenshot_is_not_blank(viewer_url: str, tmp_path: Path) -> None:
    chromium = _chromium()
    wrapper = _wrapper_server(viewer_url, VIEWER_LOAD_S)
    shot = tmp_path / "viewer.png"
    try:
        subprocess.run([
            chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
            "--no-first-run", "--disable-background-networking", "--disable-component-update",
            "--disable-sync", f"--user-data-dir={tmp_path / 'profile'}",
            # WebGL through the software rasterizer: there is no GPU in CI.
            "--enable-unsafe-swiftshader",
            "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE localhost, EXCLUDE 127.0.0.1",
            f"--window-size={WINDOW[0]},{WINDOW[1]}", f"--screenshot={shot}",
            f"http://127.0.0.1:{wrapper.server_address[1]}/",
        ], check=True, capture_output=True, timeout=VIEWER_LOAD_S + 90)
    finally:
        wrapper.shutdown()
    image = np.asarray(Image.open(shot).convert("RGB")).astype(float)
    assert image.shape == (WINDOW[1], WINDOW[0], 3)
    assert image.std() > 20.0, "blank screenshot"
    # The viewer drew our data, not only its own UI: the orange 'actual' series and track.
    orange = np.abs(image - ORANGE).max(axis=2) < 40
    assert orange.sum() > 500, "no data drawn (orange series/track missing)"
    if out := os.environ.get("ITT_SCREENSHOT_OUT"):
        # Without the white band Chromium leaves below the viewer.
        page = Image.open(shot).convert("RGB")
        page.crop(ImageOps.invert(page).getbbox()).save(out)
