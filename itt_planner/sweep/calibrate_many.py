"""Calibration at scale: many riders' ride folders fitted in parallel on the sweep's Ray engine.

One folder per rider (its name is the rider's name), holding that rider's ride files
(`.fit`, `.tcx`, `.gpx`, `.csv`). The driver reads the files and sends their bytes with
the task, so worker nodes need no shared file system; a task writes them to a private
temporary folder, runs `calibration.calibrate` on them (each ride's own track as its
course) and returns the summary and the rider YAML. A rider whose fit is refused or
fails is reported with the reason and the others go on. The driver writes
`<rider>.rider.yaml` for every fitted rider and `calibration.json` (all summaries) to the
output folder.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import socket
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from itt_planner.course.track_files import SUFFIXES, track_format
from itt_planner.errors import IttError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RiderRides:
    """One rider's ride files, read on the driver: (file name, bytes)."""

    name: str
    files: tuple[tuple[str, bytes], ...]


def read_folders(folders: list[str | Path]) -> list[RiderRides]:
    """Every folder's ride files (sorted by name).

    Raises:
        IttError: a folder that does not exist or holds no ride file, or a rider name twice.
    """
    out: dict[str, RiderRides] = {}
    for folder in map(Path, folders):
        if not folder.is_dir():
            raise IttError(f"{folder}: not a folder of ride files")
        files = sorted(p for p in folder.iterdir() if track_format(p))
        if not files:
            raise IttError(f"{folder}: no ride file ({', '.join(SUFFIXES)}, or gzipped)")
        if folder.name in out:
            raise IttError(f"{folder}: a second folder named {folder.name!r} (rider names "
                           "come from the folder names)")
        out[folder.name] = RiderRides(folder.name, tuple((p.name, p.read_bytes()) for p in files))
    return list(out.values())


def calibrate_rider(rides: RiderRides, options: Any) -> dict[str, Any]:
    """Fit one rider (never raises: a refusal or error is the row's `reason`)."""
    from itt_planner.calibration import calibrate, rider_yaml  # noqa: PLC0415

    t0 = time.perf_counter()
    row: dict[str, Any] = {"rider": rides.name, "rides": [n for n, _ in rides.files],
                           "hostname": socket.gethostname()}
    try:
        import ray  # noqa: PLC0415

        row["node_id"] = ray.get_runtime_context().get_node_id() if ray.is_initialized() else ""
    except ImportError:
        row["node_id"] = ""
    with tempfile.TemporaryDirectory(prefix="itt_calibrate_") as tmp:
        paths = []
        for name, data in rides.files:
            path = Path(tmp, name)
            path.write_bytes(data)
            paths.append(path)
        try:
            result = calibrate(paths, dataclasses.replace(options, name=rides.name))
        except Exception as err:  # noqa: BLE001 - one rider's failure is its row, not the run's
            reason = f"{type(err).__name__}: {err}".replace(tmp + "/", "")
            return {**row, "status": "failed", "reason": reason,
                    "wall_s": time.perf_counter() - t0}
        text = rider_yaml(result).replace(tmp + "/", "")  # name the files, not our temp folder
    summary = result.as_dict()
    summary["rides"] = row["rides"]
    return {**row, "status": "fitted", "reason": "; ".join(f"{k}: {v}" for k, v in
                                                          result.refusals.items()),
            "summary": summary, "rider_yaml": text, "wall_s": time.perf_counter() - t0}


def calibrate_many(folders: list[str | Path], output: str | Path, options: Any, *,
                   address: str | None = None, workers: int | None = None,
                   progress: bool = False) -> dict[str, Any]:
    """Fit every folder's rider on Ray and write the riders and `calibration.json`.

    Raises:
        IttError: unusable folders, the output cannot be written, Ray not available.
    """
    from itt_planner.sweep.cluster import ray_session  # noqa: PLC0415

    riders = read_folders(folders)
    output = Path(output)
    t0 = time.perf_counter()
    rows = []
    with ray_session(address, workers) as session:
        import ray  # noqa: PLC0415

        task = ray.remote(num_cpus=1, max_retries=0)(calibrate_rider)
        pending = {task.remote(r, options): r for r in riders}
        with tqdm(total=len(riders), desc="calibrate", unit="rider", file=sys.stderr,
                  disable=not progress) as bar:
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                rides = pending.pop(ready[0])
                try:
                    rows.append(ray.get(ready[0]))
                except (ray.exceptions.RayTaskError, ray.exceptions.RayActorError,
                        ray.exceptions.WorkerCrashedError) as err:
                    rows.append({"rider": rides.name, "status": "failed",
                                 "reason": f"the worker failed: {type(err).__name__}"})
                bar.update(1)
        cpus = session.cpus
    try:
        output.mkdir(parents=True, exist_ok=True)
        for row in rows:
            if row["status"] == "fitted":
                path = output / f"{row['rider']}.rider.yaml"
                path.write_text(row.pop("rider_yaml"), encoding="utf-8")
                row["output"] = str(path)
        (output / "calibration.json").write_text(json.dumps(rows, indent=1, default=str))
    except OSError as err:
        raise IttError(f"{output}: cannot write the calibrated riders ({err})") from None
    failed = [r["rider"] for r in rows if r["status"] != "fitted"]
    if failed:
        log.warning("calibration failed for %d of %d riders: %s", len(failed), len(rows),
                    ", ".join(failed))
    return {"output": str(output), "riders": len(rows), "fitted": len(rows) - len(failed),
            "failed": failed, "cpus": cpus, "wall_s": round(time.perf_counter() - t0, 2),
            "nodes": sorted({r.get("node_id", "") for r in rows} - {""})}
