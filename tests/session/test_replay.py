"""The embedded replay: a whole ride through the pacing engine, deterministic, nothing lost."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from mcap.reader import make_reader
from support.mcap_readers import check_all_readers, rerun_value
from typer.testing import CliRunner

from itt_planner.cli import app
from itt_planner.errors import IttError, RideLogError
from itt_planner.live.advice import Advice
from itt_planner.live.engine import ON_PLAN, EngineSettings, PacingEngine
from itt_planner.logs.ridelog import RawRecord, RideLogReader
from itt_planner.logs.ridelog_writer import RideLogWriter, RideMetadata
from itt_planner.model.conditions import Conditions, air_density_kgpm3
from itt_planner.model.rider import PRESETS
from itt_planner.ocp.cache import load_or_solve
from itt_planner.ocp.course_settings import OcpSettings
from itt_planner.ocp.horizon import HorizonPlanner
from itt_planner.ocp.horizon_settings import HorizonSettings
from itt_planner.ocp.plan import Plan
from itt_planner.ocp.solver import PlanStatus
from itt_planner.session import replay as replay_mod
from itt_planner.session.config import NO_WALL_TIME_LIMIT_S, SessionConfig, ride_setup
from itt_planner.session.replay import ReplaySettings, parse_speed, replay
from itt_planner.session.ride_session import RideSession
from itt_planner.sim import hairpin_course, sensor_samples
from itt_planner.view.ride_report import load_ride_trace

if TYPE_CHECKING:
    from itt_planner.view.rerun_log import RideRecorder

T0 = 1_779_000_000.0
REPLAN_S = 10.0  # few solves keep the tests short; the benchmark replans at 1 Hz
HORIZON_M = 500.0
INPUTS = ("/itt/gps/fix", "/itt/speed", "/itt/power")
#: Two replays of one log: the result and the output log of each.
Runs = list[tuple[replay_mod.ReplayResult, Path]]
OUTPUTS = {"/itt/advice": "itt_msgs/msg/Advice", "/itt/target_power": "itt_msgs/msg/TargetPower",
           "/itt/target_line": "nav_msgs/msg/Path"}


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The hairpin test course, the typical rider's plan, and a simulated ride log of it."""
    tmp = tmp_path_factory.mktemp("replay")
    course = hairpin_course()
    rider = PRESETS["typical"]
    plan = load_or_solve(course, rider, Conditions(), OcpSettings(), "1d", cache_dir=tmp)
    samples = sensor_samples(course, plan.t_s, plan.s_m, plan.n_m, plan.v_mps, plan.power_w,
                             np.random.default_rng(3), t0_s=T0)
    log = tmp / "ride.mcap"
    with RideLogWriter(log, metadata=RideMetadata(source="simulated", rider="typical")) as w:
        for sample in samples:
            w.write_sample(sample)
    # Built once (compiles CasADi Functions); no wall-time cap, as `replay_ride` does
    # for a deterministic replay.
    planner = HorizonPlanner(course, rider, plan, settings=HorizonSettings(
        horizon_m=HORIZON_M, max_wall_time_s=NO_WALL_TIME_LIMIT_S))
    return {"course": course, "rider": rider, "plan": plan, "log": log, "tmp": tmp,
            "n_in": len(samples), "planner": planner}


def session_for(setup: dict[str, Any], output: Path | None = None,
                recorder: RideRecorder | None = None) -> RideSession:
    """A session on a fresh engine; the shared planner forgets its warm start from the
    last replay."""
    setup["planner"].reset()
    engine = PacingEngine(setup["course"], setup["rider"], setup["plan"],
                          planner=setup["planner"],
                          settings=EngineSettings(replan_period_s=REPLAN_S, deterministic=True))
    writer = RideLogWriter(output) if output is not None else None
    return RideSession(SessionConfig(replan_period_s=REPLAN_S, horizon_m=HORIZON_M,
                                     deterministic=True),
                       engine, writer=writer, recorder=recorder)


@pytest.fixture(scope="module")
def two_runs(setup: dict[str, Any]) -> Runs:
    runs = []
    for i in range(2):
        out = setup["tmp"] / f"advice{i}.mcap"
        runs.append((replay(setup["log"], session_for(setup, out)), out))
    return runs


def payloads(path: Path, topic: str) -> list[bytes]:
    with path.open("rb") as f:
        return [m.data for _, c, m in make_reader(f).iter_messages(topics=[topic])]


def test_advice_for_the_whole_ride(setup: dict[str, Any], two_runs: Runs) -> None:
    result, out = two_runs[0]
    assert result.errors == [] and result.messages_in == setup["n_in"]
    duration = setup["plan"].finish_time_s
    assert result.ride_duration_s == pytest.approx(duration, abs=2.0)
    assert result.advice_out >= 0.9 * duration / REPLAN_S
    advice = [v for _, _, v in RideLogReader(out) if isinstance(v, Advice)]
    assert len(advice) == result.advice_out
    # Advice until the end: the last one within a replan period of the last input.
    last_in = max(s for t, s, _ in RideLogReader(out) if t in INPUTS)
    assert advice[-1].stamp_s > last_in - REPLAN_S
    assert advice[-1].state.s_m > setup["course"].length_m - 20 * REPLAN_S
    # Planner quality is tested with the planner; here: good advice (the plan while the
    # rider is on it, solved replans otherwise) reaches the output.
    assert any(not a.fallback and (a.solver_status == ON_PLAN
                                   or PlanStatus.of(a.solver_status) is PlanStatus.CONVERGED)
               for a in advice)
    assert all(a.solve_time_s == 0.0 for a in advice)  # deterministic mode
    powers = np.array([a.target_power_w for a in advice if a.solver_status != "finished"])
    assert np.all(np.isfinite(powers)) and 100 < np.median(powers) < 600


def test_output_holds_every_input_and_output_message(setup: dict[str, Any], two_runs: Runs,
                                                     tmp_path: Path) -> None:
    result, out = two_runs[0]
    for topic in INPUTS:  # copied byte for byte
        assert payloads(out, topic) == payloads(setup["log"], topic)
    n = result.advice_out
    n_diag = result.topics_out["/diagnostics"]
    # The replay's timer: one advice per replan period, diagnostics once a second.
    assert n == pytest.approx(result.ride_duration_s / REPLAN_S, abs=1.5)
    assert n_diag == pytest.approx(result.ride_duration_s, abs=1.5)
    expected = {t: (ty, n) for t, ty in OUTPUTS.items()}
    expected["/diagnostics"] = ("diagnostic_msgs/msg/DiagnosticArray", n_diag)
    in_types = {"/itt/gps/fix": "sensor_msgs/msg/NavSatFix",
                "/itt/speed": "geometry_msgs/msg/TwistStamped",
                "/itt/power": "itt_msgs/msg/PowerStamped"}
    for t in INPUTS:
        expected[t] = (in_types[t], len(payloads(setup["log"], t)))
    assert result.topics_out == {t: c for t, (_, c) in expected.items()}
    got = check_all_readers(out, expected, tmp_path)
    ours = [v for _, _, v in RideLogReader(out) if isinstance(v, Advice)]
    k = len(ours) // 2
    assert got["rosbags"]["/itt/advice"][k].target_power_w == ours[k].target_power_w
    assert got["mcap_ros2"]["/itt/target_power"][k].power_w == ours[k].target_power_w
    line = rerun_value(got["rerun"]["/itt/target_line"][k])
    assert [p["pose"]["position"]["x"] for p in line["poses"]] == pytest.approx(ours[k].line_x_m)
    times = [r.log_time_ns for r in RideLogReader(out).records()]
    assert times == sorted(times)  # written in stamp order, advice after its inputs
    with out.open("rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert meta["itt_ride"]["source"] == "simulated"


def test_replay_is_deterministic(two_runs: Runs) -> None:
    (a, out_a), (b, out_b) = two_runs
    assert a.advice_out == b.advice_out
    for topic in ("/itt/advice", "/itt/target_power", "/itt/target_line"):
        assert payloads(out_a, topic) == payloads(out_b, topic)


def test_damaged_input_replays_everything_before_the_damage(setup: dict[str, Any],
                                                             tmp_path: Path) -> None:
    # An unknown topic rides along: copied to the output, skipped by the engine.
    extra = tmp_path / "extra.mcap"
    with RideLogWriter(extra) as w:
        for raw in RideLogReader(setup["log"]).records():
            w.write_raw(raw)
            if raw.topic == "/itt/power":
                w.write_raw(RawRecord("/rosout", "std_msgs/msg/String", "ros2msg",
                                      b"string data\n", "cdr", raw.log_time_ns,
                                      raw.log_time_ns, b"\x00\x01\x00\x00\x01\x00\x00\x00\x00"))
    cut_extra = tmp_path / "cut_extra.mcap"
    cut_extra.write_bytes(extra.read_bytes()[: int(extra.stat().st_size * 0.6)])
    out = tmp_path / "out.mcap"
    result = replay(cut_extra, session_for(setup, out))
    assert len(result.errors) == 1 and "cut_extra.mcap: truncated" in result.errors[0]
    assert any("unknown topic /rosout" in w for w in result.warnings)
    reader = RideLogReader(out)
    read = list(reader)
    assert reader.errors == []  # the output itself is whole
    n_in = sum(1 for t, _, _ in read if t in INPUTS)
    assert n_in == result.messages_in - reader.skipped["/rosout"] > 0.4 * setup["n_in"]
    advice = [v for _, _, v in read if isinstance(v, Advice)]
    assert len(advice) == result.advice_out >= 0.5 * setup["plan"].finish_time_s / REPLAN_S
    last_in = max(s for t, s, _ in read if t in INPUTS)
    assert advice[-1].stamp_s == pytest.approx(last_in, abs=REPLAN_S)


def test_rerun_recording(setup: dict[str, Any], tmp_path: Path) -> None:
    from rerun.chunk import RrdReader

    from itt_planner.view.rerun_log import RideRecorder
    from itt_planner.view.rerun_sink import RerunSink, open_recording

    rrd = tmp_path / "review.rrd"
    rec = open_recording(RerunSink("file", str(rrd)))
    recorder = RideRecorder(rec, setup["course"], setup["rider"], setup["plan"])
    recorder.log_course()
    data = setup["log"].read_bytes()
    short = tmp_path / "short.mcap"
    short.write_bytes(data[: len(data) // 4])
    result = replay(short, session_for(setup, recorder=recorder))  # flushes and disconnects
    assert result.advice_out >= 3
    entities = {c.entity_path for c in RrdReader(rrd).store().stream()}
    assert len(entities) > 5


def test_speed_paces_by_the_stamps(monkeypatch: pytest.MonkeyPatch) -> None:
    clock = [100.0]
    sleeps: list[float] = []
    monkeypatch.setattr("itt_planner.session.replay.time.perf_counter", lambda: clock[0])

    def sleep(seconds: float) -> None:
        sleeps.append(seconds)
        clock[0] += seconds

    monkeypatch.setattr("itt_planner.session.replay.time.sleep", sleep)
    pacer = replay_mod._Pacer(10.0)
    for stamp in (T0, T0 + 1.0, T0 + 3.0):
        pacer.wait(stamp)
        clock[0] += 0.01  # work per message
    assert sleeps == pytest.approx([0.09, 0.19])
    assert parse_speed("max") is None and parse_speed("10") == 10.0
    with pytest.raises(ValueError, match="positive"):
        parse_speed("-1")
    with pytest.raises(ValueError, match="> 0"):
        ReplaySettings(speed=0.0)


def test_cli_replay_json(setup: dict[str, Any], tmp_path: Path) -> None:
    data = setup["log"].read_bytes()
    short = tmp_path / "short.mcap"
    short.write_bytes(data[: len(data) // 5])  # a cut log: reported, still replayed
    course = tmp_path / "hairpin.course.npz"
    setup["course"].save(course)
    result = CliRunner().invoke(app, [
        "replay", str(short), "--course", str(course), "--rider", "typical", "--model", "1d",
        "--out", str(tmp_path / "a.mcap"), "--replan-period", str(REPLAN_S),
        "--horizon-m", str(HORIZON_M), "--cache-dir", str(setup["tmp"]), "--json"])
    assert result.exit_code == 1, result.output  # exit 1: the input was damaged
    data = json.loads(result.stdout)
    assert {"messages_in", "advice_out", "ride_duration_s", "wall_time_s", "realtime_factor",
            "output", "rrd", "warnings", "errors"} <= set(data)
    assert data["advice_out"] >= 2 and data["errors"] and data["rrd"] is None
    assert Path(data["output"]).is_file()
    assert data["conditions"] == dataclasses.asdict(Conditions())


def test_cli_replay_plans_in_the_conditions_given(setup: dict[str, Any], tmp_path: Path
                                                  ) -> None:
    """`replay --mu --wind-kmh --wind-from-deg --air-density-kgpm3`: converted at the edge
    (km/h, degrees) and said in the JSON; the plan is solved in them (it was still air at
    1.23 kg/m^3 whatever the replay was told, as no option existed)."""
    course = tmp_path / "hairpin.course.npz"
    setup["course"].save(course)
    result = CliRunner().invoke(app, [
        "replay", str(setup["log"]), "--course", str(course), "--rider", "typical",
        "--model", "1d", "--replan-period", "60", "--horizon-m", str(HORIZON_M),
        "--cache-dir", str(tmp_path / "cache"), "--mu", "0.8", "--wind-kmh", "18",
        "--wind-from-deg", "90", "--air-density-kgpm3", "1.1", "--json",
        "--out", str(tmp_path / "advice.mcap")])
    assert result.exit_code == 0, result.output
    got = json.loads(result.stdout)["conditions"]
    assert got == pytest.approx({"mu_x": 0.8, "mu_y": 0.8, "wind_speed_mps": 5.0,
                                 "wind_from_rad": math.pi / 2, "air_density_kgpm3": 1.1})
    cached = [Plan.load(p) for p in (tmp_path / "cache").rglob("*.npz")]
    assert cached and all(p.meta["conditions"] == got for p in cached)
    # Its report compares the ride with that plan (it took the still-air one).
    _, _, plan = ride_setup(load_ride_trace(tmp_path / "advice.mcap"), None, None,
                            tmp_path / "cache")
    assert plan.meta["conditions"] == got
    # A session advised from a plan file: the report takes that plan, or says it is gone.
    trace = load_ride_trace(tmp_path / "advice.mcap")
    trace.metadata["plan"] = str(tmp_path / "gone.plan.npz")
    with pytest.raises(IttError, match=r"advised from plan .*gone\.plan\.npz, which is not here"):
        ride_setup(trace, None, None, tmp_path / "cache")
    cached[0].save(tmp_path / "kept.plan.npz")
    trace.metadata["plan"] = str(tmp_path / "kept.plan.npz")
    assert ride_setup(trace, None, None, tmp_path / "cache")[2].finish_time_s == \
        cached[0].finish_time_s


def test_cli_replay_advises_from_a_plan_file(setup: dict[str, Any], tmp_path: Path) -> None:
    """`replay --plan` (the node's `plan`): the session rides the saved plan, in its own
    conditions, and says so in its log; a plan of another course is refused by name."""
    course = tmp_path / "hairpin.course.npz"
    setup["course"].save(course)
    windy = Conditions.from_meteo(wind_kmh=12.0, wind_from_deg=180.0)
    plan_file = load_or_solve(setup["course"], setup["rider"], windy, OcpSettings(), "1d",
                              cache_dir=tmp_path / "cache").save(tmp_path / "windy.plan.npz")
    args = ["replay", str(setup["log"]), "--rider", "typical", "--model", "1d",
            "--plan", str(plan_file), "--replan-period", "60", "--horizon-m", str(HORIZON_M),
            "--cache-dir", str(tmp_path / "empty"), "--json"]
    result = CliRunner().invoke(app, [*args, "--course", str(course),
                                      "--out", str(tmp_path / "advice.mcap")])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["conditions"] == pytest.approx(dataclasses.asdict(windy))
    assert load_ride_trace(tmp_path / "advice.mcap").metadata["plan"] == str(plan_file)
    assert not (tmp_path / "empty").exists() or not list((tmp_path / "empty").rglob("*.npz"))
    result = CliRunner().invoke(app, [*args, "--course", "verona-like"])
    assert result.exit_code == 1, result.output
    assert "windy.plan.npz was solved on course" in json.loads(result.stdout)["error"]


def test_cli_replay_refuses_an_unknown_resolve_model(tmp_path: Path) -> None:
    """`--course-resolve-model` takes what `CourseReplanSettings.model` does: anything else
    is one JSON error naming the option, before any input is read."""
    result = CliRunner().invoke(app, [
        "replay", str(tmp_path / "none.mcap"), "--course", "verona-like", "--rider", "typical",
        "--course-resolve-model", "2d", "--json"])
    assert result.exit_code == 1, result.output
    error = json.loads(result.stdout)
    assert "--course-resolve-model '2d'" in error["error"] and "1d-line" in error["error"]


def test_a_log_of_other_topics_is_an_error_and_remap_reads_it(setup: dict[str, Any],
                                                              tmp_path: Path) -> None:
    """A log recorded from another driver's topics gave 0 advice and exit 0; now an error
    naming what the engine reads and what the log has, and `--remap` reads it as
    `ros2 bag play --remap` would."""
    names = {"/itt/gps/fix": "/fix", "/itt/speed": "/bike/speed", "/itt/power": "/bike/power"}
    short = tmp_path / "short.mcap"
    with RideLogWriter(short) as w:
        for k, raw in enumerate(RideLogReader(setup["log"]).records()):
            if k < setup["n_in"] // 5:
                w.write_raw(raw._replace(topic=names[raw.topic]))
    result = replay(short, session_for(setup))
    assert result.advice_out == 0 and len(result.errors) == 1
    assert all(t in result.errors[0] for t in (*names, *names.values(), "--remap"))
    remap = replay_mod.parse_remap([f"{b}:={a}" for a, b in names.items()])
    result = replay(short, session_for(setup), settings=ReplaySettings(remap=remap))
    assert result.errors == [] and result.advice_out >= 2
    with pytest.raises(ValueError, match="LOG_TOPIC:=PACING_TOPIC"):
        replay_mod.parse_remap(["fix:=/itt/gps/fix"])
    with pytest.raises(RideLogError, match="--remap to /itt/gps: not a topic the engine reads"):
        replay(short, session_for(setup), settings=ReplaySettings(remap=(("/fix", "/itt/gps"),)))


def test_cli_replay_the_days_air(setup: dict[str, Any], tmp_path: Path) -> None:
    """A ride log that says the day's air temperature (`import`: the median of the
    records'): the replay in the paper's air says what the day's air was and how to plan
    in it; `--air-temperature-c` plans in it, at the course's altitude."""
    course = tmp_path / "hairpin.course.npz"
    setup["course"].save(course)
    plan = setup["plan"]
    log = tmp_path / "hot.mcap"
    with RideLogWriter(log, metadata=RideMetadata(source="simulated", air_temperature_c=35.0)
                       ) as w:
        for sample in sensor_samples(setup["course"], plan.t_s, plan.s_m, plan.n_m, plan.v_mps,
                                     plan.power_w, np.random.default_rng(3), t0_s=T0):
            w.write_sample(sample)
    args = ["replay", str(log), "--course", str(course), "--rider", "typical", "--model", "1d",
            "--replan-period", "60", "--horizon-m", str(HORIZON_M),
            "--cache-dir", str(tmp_path / "cache"), "--json"]
    paper = json.loads(CliRunner().invoke(app, args).stdout)
    [note] = [w for w in paper["warnings"] if "air" in w]
    assert "records give 35.0 C" in note and "--air-temperature-c 35.0" in note
    hot = json.loads(CliRunner().invoke(app, [*args, "--air-temperature-c", "35"]).stdout)
    assert not [w for w in hot["warnings"] if "air" in w]
    assert hot["conditions"]["air_temperature_c"] == 35.0
    assert hot["conditions"]["air_density_kgpm3"] == pytest.approx(
        float(air_density_kgpm3(setup["course"].mean_altitude_m, 35.0)))
    both = CliRunner().invoke(app, [*args, "--air-temperature-c", "35",
                                    "--air-density-kgpm3", "1.1"])
    assert both.exit_code == 1 and "give one" in json.loads(both.stdout)["error"]
