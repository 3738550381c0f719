"""Scenario sweeps on Ray (`itt_planner.sweep`, `itt-planner sweep`, `sweep-report`).

The default suite runs one small sweep on a private local Ray instance (2 riders x 2
winds x dry/wet in 1D, one rider's 2 winds x dry/wet in 3D, on a 1.2 km built course,
plus one case on a road narrower than the bike: listed `cases`), interrupted after a few
cases and resumed: the table must hold every case once, the finish times must be those of
direct `solve_plan` calls (a subset covering every axis value), the impossible case must
be a failed row with its reason, and every socket of the Ray instance must be on loopback.
The two-node test (`slow`) starts a head and a second node with `ray start` on 127.0.0.1
and runs the CLI through `--address`.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil
import pytest
import yaml
from support.courses import SHORT
from typer.testing import CliRunner

from itt_planner.cli import app
from itt_planner.course.loader import load_course
from itt_planner.model.conditions import Conditions
from itt_planner.model.rider import PRESETS, load_rider
from itt_planner.ocp.course_problem import solve_plan
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.sweep import (
    CONVERGED,
    FAILED,
    ResultStore,
    SweepSpecError,
    load_spec,
    parse_spec,
    run_sweep,
    solve_case,
)
from itt_planner.sweep.cases import expand, load_inputs
from itt_planner.sweep.spec import Equipment

ROOT = Path(__file__).resolve().parents[2]
RAY = Path(sys.executable).with_name("ray")

#: The same road 0.4 m wide: narrower than the bike and its margins, no solver can use it.
NARROW = {**SHORT, "name": "narrow", "width_left_m": 0.2, "width_right_m": 0.2}
WINDS_KMH = (0.0, 40.0)
GRIPS = (1.0, 0.6)
#: Cases of the short course: two riders in 1D, one in 3D (the slow solves), every wind
#: and grip.
N_SHORT = (2 + 1) * len(WINDS_KMH) * len(GRIPS)
INTERRUPT_AFTER = 6


def _write_spec(folder: Path, name: str = "eve") -> Path:
    (folder / "short.yaml").write_text(yaml.safe_dump(SHORT))
    (folder / "narrow.yaml").write_text(yaml.safe_dump(NARROW))
    spec = {"name": name, "courses": ["short.yaml", "narrow.yaml"],
            "riders": ["typical", "climber"],
            "axes": {"model": ["1d", "3d"], "wind_kmh": list(WINDS_KMH), "wind_from_deg": [90],
                     "mu": list(GRIPS)},
            "cases": [{"course": "short.yaml", "model": "1d"},
                      {"course": "short.yaml", "model": "3d", "rider": "typical"},
                      {"course": "narrow.yaml", "rider": "typical", "model": "1d",
                       "wind_kmh": 0, "mu": 1.0}]}
    path = folder / f"{name}.sweep.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def _listening(pids: list[int]) -> list[tuple[int, str, str, int]]:
    """(pid, name, address, port) of every listening TCP / bound UDP socket of `pids`."""
    out: list[tuple[int, str, str, int]] = []
    for pid in pids:
        try:
            proc = psutil.Process(pid)
            out.extend((pid, proc.name(), c.laddr.ip, c.laddr.port)
                       for c in proc.net_connections(kind="inet")
                       if c.status in (psutil.CONN_LISTEN, psutil.CONN_NONE) and c.laddr)
        except psutil.Error:
            continue
    return out


def _loopback(ip: str) -> bool:
    return ip in ("127.0.0.1", "::ffff:127.0.0.1", "::1")


class _Interrupt(KeyboardInterrupt):
    """Ctrl-C, raised from the row callback after a few cases."""


@pytest.fixture(scope="module")
def swept(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The small sweep, interrupted after INTERRUPT_AFTER cases, then resumed."""
    folder = tmp_path_factory.mktemp("sweep")
    spec = load_spec(_write_spec(folder))
    out = folder / "results.parquet"
    sockets: list[tuple[int, str, str, int]] = []
    first_rows: list[dict[str, Any]] = []

    def stop_early(row: dict[str, Any]) -> None:
        first_rows.append(row)
        if len(first_rows) == 1:  # Ray is up: what does it listen on?
            sockets.extend(_listening([p.pid for p in psutil.Process().children(recursive=True)]))
        if len(first_rows) == INTERRUPT_AFTER:
            raise _Interrupt

    with pytest.raises(_Interrupt):
        run_sweep(spec, out, workers=2, batch_size=2, on_row=stop_early)
    recorded_after_interrupt = ResultStore(out).recorded()
    resumed = run_sweep(spec, out, workers=2)
    return {"spec": spec, "out": out, "first_rows": first_rows, "sockets": sockets,
            "after_interrupt": recorded_after_interrupt, "resumed": resumed, "folder": folder}


def test_sweep_resumes_without_solving_a_case_twice(swept: dict[str, Any]) -> None:
    courses, riders = load_inputs(swept["spec"])
    keys = {c.key for c in expand(swept["spec"], courses, riders)}
    assert len(keys) == N_SHORT + 1
    # Every case finished before the interrupt was written on the way out.
    assert swept["after_interrupt"] == {r["key"] for r in swept["first_rows"]}
    resumed = swept["resumed"]
    assert resumed.already_done == INTERRUPT_AFTER
    assert resumed.solved == len(keys) - INTERRUPT_AFTER
    raw = ResultStore(swept["out"]).read_raw().to_pylist()
    assert Counter(r["key"] for r in raw) == dict.fromkeys(keys, 1)  # one row per case, ever
    assert len(ResultStore(swept["out"]).parts()) == 1  # compacted after the complete run
    # Nothing left to do: a third run solves nothing and starts no Ray.
    again = run_sweep(swept["spec"], swept["out"])
    assert (again.already_done, again.solved) == (len(keys), 0)


def test_sweep_matches_direct_plans(swept: dict[str, Any]) -> None:
    rows = [r for r in ResultStore(swept["out"]).read().to_pylist()
            if r["course"].endswith("short.yaml")]
    assert len(rows) == N_SHORT and all(r["status"] == CONVERGED for r in rows), \
        [(r["rider"], r["model"], r["reason"]) for r in rows if r["status"] != CONVERGED]
    course = load_course(swept["folder"] / "short.yaml")
    # Solved again directly: a subset in which every value of every axis occurs (each row
    # comes out of the same code path; 4 solves instead of N_SHORT).
    covering = {("typical", "1d", 0, 1.0), ("climber", "1d", 40, 0.6),
                ("typical", "3d", 0, 0.6), ("typical", "3d", 40, 1.0)}
    picked = [r for r in rows
              if (r["rider"], r["model"], round(r["wind_speed_mps"] * 3.6), r["mu"]) in covering]
    assert len(picked) == len(covering)
    for r in picked:
        conditions = Conditions(mu_x=r["mu"], mu_y=r["mu"], wind_speed_mps=r["wind_speed_mps"],
                                wind_from_rad=r["wind_from_rad"])
        plan = solve_plan(course, PRESETS[r["rider"]], conditions, OcpSettings(), model=r["model"])
        assert plan.meta["success"]
        assert r["finish_time_s"] == pytest.approx(plan.finish_time_s, rel=1e-9), r
        assert r["solver_status"] == plan.solver_status
        assert r["split_elapsed_s"][-1] == pytest.approx(plan.finish_time_s, rel=1e-9)
    # Physics sanity of the table: the 40 km/h wind from the east (a headwind on the
    # long eastward straight) costs time, the wet costs time in 3D; and each row says
    # where it ran.
    finish = {(r["rider"], r["model"], round(r["wind_speed_mps"] * 3.6), r["mu"]):
              r["finish_time_s"] for r in rows}
    assert finish[("typical", "3d", 40, 1.0)] > finish[("typical", "3d", 0, 1.0)]
    assert finish[("typical", "3d", 0, 0.6)] > finish[("typical", "3d", 0, 1.0)]
    assert finish[("climber", "1d", 40, 1.0)] > finish[("climber", "1d", 0, 1.0)]
    assert all(r["node_id"] and r["hostname"] and r["pid"] for r in rows)
    assert len({r["pid"] for r in rows}) >= 2  # two worker actors shared the cases


def test_failing_case_is_recorded_and_the_sweep_goes_on(swept: dict[str, Any]) -> None:
    rows = ResultStore(swept["out"]).read().to_pylist()
    failed = [r for r in rows if r["status"] == FAILED]
    assert len(failed) == 1
    (bad,) = failed
    assert bad["course"].endswith("narrow.yaml") and bad["solver_status"] == "invalid_input"
    assert "narrower than the bike" in bad["reason"]
    assert bad["finish_time_s"] is None
    assert sum(r["status"] == CONVERGED for r in rows) == N_SHORT


def test_local_ray_listens_on_loopback_only(swept: dict[str, Any]) -> None:
    sockets = swept["sockets"]
    names = {name for _, name, _, _ in sockets}
    assert {"gcs_server", "raylet"} <= names, names  # we did see Ray's servers
    outside = [s for s in sockets if not _loopback(s[2])]
    assert not outside, outside


def test_sweep_report(swept: dict[str, Any], tmp_path: Path) -> None:
    result = CliRunner().invoke(app, ["sweep-report", str(swept["out"]), "-o",
                                      str(tmp_path / "sweep.html"), "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    # Wind heatmap (the narrow course has no converged case), wet cost, 3D - 1D.
    assert info["figures"] == 3 and info["converged"] == N_SHORT and info["cases"] == N_SHORT + 1
    page = (tmp_path / "sweep.html").read_text()
    assert page.count("data:image/png;base64,") == 3
    assert "narrower than the bike" in page  # the failed case is listed with its reason


def test_sweep_cli_resumes_a_complete_sweep_and_rejects_a_bad_spec(swept: dict[str, Any],
                                                                    tmp_path: Path) -> None:
    spec = swept["folder"] / "eve.sweep.yaml"
    result = CliRunner().invoke(app, ["sweep", str(spec), "-o", str(swept["out"]), "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    assert (info["cases"], info["already_done"], info["solved"]) == (N_SHORT + 1, N_SHORT + 1, 0)
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"courses": ["verona-like"], "riders": ["typical"],
                                   "axes": {"mu": [1.0, 0.0]}}))
    result = CliRunner().invoke(app, ["sweep", str(bad), "-o", str(tmp_path / "r"), "--json"])
    assert result.exit_code == 1
    err = json.loads(result.stdout)
    assert err["type"] == "SweepSpecError" and "axes.mu" in err["error"]
    assert "bad.yaml" in err["error"]


# ---- without Ray ---------------------------------------------------------------------------

def test_spec_errors_name_the_field(tmp_path: Path) -> None:
    base = {"courses": ["verona-like"], "riders": ["typical"]}
    bad = [({**base, "axes": {"wind_kmh": [-5]}}, "axes.wind_kmh"),
           ({**base, "axes": {"mu": ["wet"]}}, "axes.mu"),
           ({**base, "axes": {"model": ["2d"]}}, "axes.model"),
           ({**base, "axes": {"wprime_model": ["bartram"]}}, "axes.wprime_model"),
           ({**base, "axes": {"equipment": {"aero": {"cda": 0.2}}}}, "axes.equipment.aero"),
           ({**base, "axes": {"gradient": [1]}}, "axes: unknown key(s) gradient"),
           ({**base, "riders": ["nobody"]}, "riders: 'nobody'"),
           ({**base, "solver": {"max_iter": "many"}}, "solver.max_iter"),
           ({**base, "cases": [{"rider": "climber"}]}, "cases[0].rider"),
           ({**base, "cases": [{"equipment": "disc"}]}, "cases[0].equipment")]
    for raw, field in bad:
        with pytest.raises(SweepSpecError, match=field.replace("[", r"\[").replace("]", r"\]")
                           .replace("(", r"\(").replace(")", r"\)")):
            parse_spec(raw, base_dir=tmp_path)
    spec = parse_spec({**base, "axes": {"wind_kmh": [0, 36], "wind_from_deg": [450]}})
    assert spec.grids[0].wind_speeds_mps == (0.0, 10.0)
    assert spec.grids[0].wind_from_rad == pytest.approx((math.pi / 2,))


def test_equipment_and_case_keys(tmp_path: Path) -> None:
    (tmp_path / "short.yaml").write_text(yaml.safe_dump(SHORT))
    spec = parse_spec({"courses": ["short.yaml"], "riders": ["typical"],
                       "axes": {"model": ["1d"], "equipment": {
                           "stock": {}, "aero": {"drag_area_m2": 0.2},
                           "lighter": {"delta_mass_kg": -2.0}, "broken": {"delta_mass_kg": -90}}}},
                      base_dir=tmp_path)
    cases = expand(spec, *load_inputs(spec))
    assert len({c.key for c in cases}) == 4
    again = expand(spec, *load_inputs(spec))
    assert [c.key for c in again] == [c.key for c in cases]  # keys are stable
    lighter = Equipment("lighter", delta_fields=(("mass_kg", -2.0),)).apply(PRESETS["typical"])
    assert lighter.mass_kg == PRESETS["typical"].mass_kg - 2.0
    course = load_course(tmp_path / "short.yaml")
    rows = {c.equipment.name: solve_case(course, c) for c in cases}
    assert rows["broken"]["status"] == FAILED and "mass_kg" in rows["broken"]["reason"]
    assert rows["aero"]["finish_time_s"] < rows["stock"]["finish_time_s"]  # 0.2 < 0.26 m^2
    assert rows["lighter"]["finish_time_s"] < rows["stock"]["finish_time_s"]


def test_store_appends_parts_and_keeps_the_latest_row(tmp_path: Path) -> None:
    store = ResultStore(tmp_path / "r.parquet")
    assert store.read().num_rows == 0 and store.recorded() == set()
    store.append([{"key": "a", "status": FAILED, "finished_unix_s": 1.0}])
    store.append([{"key": "b", "status": CONVERGED, "finish_time_s": 60.0, "finished_unix_s": 2.0},
                  {"key": "a", "status": CONVERGED, "finish_time_s": 61.0, "finished_unix_s": 3.0}])
    assert len(store.parts()) == 2 and store.read_raw().num_rows == 3
    assert store.recorded(statuses=(CONVERGED,)) == {"a", "b"}
    assert store.read().num_rows == 2
    store.compact()
    assert len(store.parts()) == 1
    latest = {r["key"]: r["finish_time_s"] for r in store.read().to_pylist()}
    assert latest == {"a": 61.0, "b": 60.0}
    assert not list((tmp_path / "r.parquet").glob(".*"))  # no temporary file left behind
    (tmp_path / "file.parquet").write_text("x")
    with pytest.raises(Exception, match="is a file"):
        ResultStore(tmp_path / "file.parquet")


def test_calibrate_many_fits_riders_in_parallel(tmp_path: Path) -> None:
    """Two riders' folders on local Ray: a real ride is fitted, a broken file is reported."""
    (tmp_path / "stjohns").mkdir()
    (tmp_path / "stjohns" / "ride.fit").write_bytes(
        (ROOT / "tests" / "data" / "edge810_vector_stjohns_2013.fit").read_bytes())
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "ride.fit").write_bytes(b"not a FIT file")
    out = tmp_path / "riders"
    result = CliRunner().invoke(app, ["calibrate-many", str(tmp_path / "stjohns"),
                                      str(tmp_path / "broken"), "-o", str(out),
                                      "--workers", "2", "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    assert (info["riders"], info["fitted"], info["failed"]) == (2, 1, ["broken"])
    rows = {r["rider"]: r for r in json.loads((out / "calibration.json").read_text())}
    assert "not a valid FIT file" in rows["broken"]["reason"]
    assert "/tmp/itt_calibrate" not in rows["broken"]["reason"]
    rider = load_rider(out / "stjohns.rider.yaml")
    assert rider.name == "stjohns"
    fitted = rows["stjohns"]["summary"]["rider"]
    assert rider.critical_power_w == pytest.approx(fitted["critical_power_w"], rel=1e-3)
    assert 150 < rider.critical_power_w < 450 and 0.15 < rider.drag_area_m2 < 0.6


# ---- two Ray nodes on 127.0.0.1, joined with --address ------------------------------------

#: `ray start` for a second node on 127.0.0.1. Ray 2.60 rewrites 127.0.0.1 to the outward IP
#: unless RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0 (see itt_planner/sweep/cluster.py), and with
#: that variable `ray start` refuses to add a node ("multi-node clusters are not supported
#: on Windows and OSX"). This runs Ray's own `ray start` with only that refusal lifted: its
#: module sees the flag on, the address resolution (services) sees it off.
_SECOND_NODE = (
    "import sys, types\n"
    "import ray._private.ray_constants as constants\n"
    "import ray.scripts.scripts as scripts\n"
    "scripts.ray_constants = types.SimpleNamespace(\n"
    "    **{**vars(constants), 'ENABLE_RAY_CLUSTER': True})\n"
    "sys.argv[0] = 'ray'\n"
    "sys.exit(scripts.main())\n")


def _free_ports(n: int) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def _node_ports(ports: list[int]) -> list[str]:
    """Ports a node would otherwise take from Ray's fixed defaults (two nodes, one IP)."""
    names = ("--node-manager-port", "--object-manager-port", "--dashboard-agent-listen-port",
             "--dashboard-agent-grpc-port", "--metrics-export-port", "--runtime-env-agent-port")
    return [f"{name}={port}" for name, port in zip(names, ports, strict=True)]


def _wait_for(log: Path, text: str, proc: subprocess.Popen[bytes],
              timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if log.exists() and text in log.read_text(errors="replace"):
            return
        if proc.poll() is not None:
            pytest.fail(f"ray start exited with {proc.returncode}:\n{log.read_text()[-3000:]}")
        time.sleep(0.5)
    pytest.fail(f"no {text!r} in {log} after {timeout_s} s:\n{log.read_text()[-3000:]}")


def _stop(procs: list[subprocess.Popen[bytes]], temp_dir: str) -> None:
    """SIGTERM the process groups we started (`ray start --block` drains its node), then
    SIGKILL whatever of them or of our Ray temp dir is left. Never `ray stop`: it stops
    every Ray process of the user on the machine, not just ours."""
    for proc in procs:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
    for proc in procs:
        try:
            proc.wait(timeout=45)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
    for p in psutil.process_iter(["pid", "cmdline"]):
        if temp_dir in " ".join(p.info["cmdline"] or []):
            with contextlib.suppress(psutil.Error):
                p.kill()
    shutil.rmtree(temp_dir, ignore_errors=True)


@pytest.fixture
def two_nodes(tmp_path: Path) -> Iterator[dict[str, Any]]:
    """A head and a second node started with `ray start`, every socket on 127.0.0.1."""
    temp_dir = tempfile.mkdtemp(prefix="ittray", dir="/tmp")  # short: Ray's unix socket paths
    gcs_port, client_port, autoscaler_port, dashboard_port, *ports = _free_ports(16)
    env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(16),
           "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0",
           "AUTOSCALER_METRIC_PORT": str(autoscaler_port),
           "DASHBOARD_METRIC_PORT": str(dashboard_port)}
    common = ["--block", "--node-ip-address=127.0.0.1", "--num-cpus=1", f"--temp-dir={temp_dir}",
              "--disable-usage-stats"]
    head_log, node_log = tmp_path / "head.log", tmp_path / "node.log"
    procs = []
    try:
        procs.append(subprocess.Popen(
            [str(RAY), "start", "--head", f"--port={gcs_port}", "--include-dashboard=false",
             f"--ray-client-server-port={client_port}", *common, *_node_ports(ports[:6])],
            env=env, start_new_session=True, stdout=head_log.open("w"), stderr=subprocess.STDOUT))
        _wait_for(head_log, "Ray runtime started", procs[0])
        procs.append(subprocess.Popen(
            [sys.executable, "-c", _SECOND_NODE, "start", f"--address=127.0.0.1:{gcs_port}",
             *common, *_node_ports(ports[6:12])],
            env=env, start_new_session=True, stdout=node_log.open("w"), stderr=subprocess.STDOUT))
        _wait_for(node_log, "Ray runtime started", procs[1])
        yield {"address": f"127.0.0.1:{gcs_port}", "env": env, "procs": procs}
    finally:
        _stop(procs, temp_dir)


@pytest.mark.slow
def test_sweep_on_two_ray_nodes(two_nodes: dict[str, Any], tmp_path: Path) -> None:
    (tmp_path / "short.yaml").write_text(yaml.safe_dump(SHORT))
    (tmp_path / "two.sweep.yaml").write_text(yaml.safe_dump({
        "name": "two-nodes", "courses": ["short.yaml"], "riders": ["typical", "climber"],
        "axes": {"model": ["1d"], "wind_kmh": list(WINDS_KMH), "mu": list(GRIPS)}}))
    out = tmp_path / "results.parquet"
    cli = Path(sys.executable).with_name("itt-planner")
    done = subprocess.run([str(cli), "sweep", str(tmp_path / "two.sweep.yaml"), "-o", str(out),
                           "--address", two_nodes["address"], "--workers", "2", "--json"],
                          env=two_nodes["env"], capture_output=True, text=True, timeout=600,
                          check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    summary = json.loads(done.stdout)
    n_cases = 2 * len(WINDS_KMH) * len(GRIPS)  # two riders, 1D
    assert summary["solved"] == n_cases and summary["counts"]["converged"] == n_cases
    assert summary["workers"] == 2 and len(summary["nodes"]) == 2, summary
    rows = ResultStore(out).read().to_pylist()
    per_node = Counter(r["node_id"] for r in rows)
    assert len(per_node) == 2 and min(per_node.values()) >= 1, per_node
    # Both nodes, and everything they started, listen on loopback only.
    pids = [q.pid for p in two_nodes["procs"]
            for q in [psutil.Process(p.pid), *psutil.Process(p.pid).children(recursive=True)]]
    sockets = _listening(pids)
    assert sum(name == "raylet" for _, name, _, _ in sockets) >= 2  # two raylets seen
    outside = [s for s in sockets if not _loopback(s[2])]
    assert not outside, outside
