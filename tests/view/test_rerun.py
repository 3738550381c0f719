"""Rerun recordings: write a synthetic ride to .rrd, read it back with rerun-sdk's reader."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rerun as rr
import rerun.blueprint as rrb
from rerun.chunk import ChunkStore, RrdReader
from support.rerun_feed import record
from support.synthetic_ride import (
    REFIT_CP_W,
    RIDER,
    T0_S,
    make_advice,
    make_course,
    make_plan,
    make_ride,
)

from itt_planner.errors import IttError
from itt_planner.live.advice import Advice, Diagnostic, Level
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.model.state import RiderState
from itt_planner.units import MPS_TO_KMH
from itt_planner.view import rerun_paths as paths
from itt_planner.view.rerun_blueprint import default_blueprint
from itt_planner.view.rerun_log import MAX_HORIZON_POINTS, TRACK_SEGMENT, RideRecorder
from itt_planner.view.rerun_sink import RerunSink, open_recording


@pytest.fixture(scope="module")
def ride(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    course = make_course()
    plan = make_plan(course)
    events = make_ride(course, plan)
    path = tmp_path_factory.mktemp("rrd") / "ride.rrd"
    rec = open_recording(RerunSink.parse(f"file:{path}"), recording_id="test-ride")
    recorder = RideRecorder(rec, course, RIDER, plan)
    recorder.log_course()
    record(recorder, events)
    # Bad inputs must be skipped and noted, not crash the ride.
    recorder.log_sample(PowerReading(T0_S + 1.0, math.nan))
    recorder.log_sample(WheelSpeed(math.inf, 10.0))
    rec.flush()
    rec.disconnect()
    reader = RrdReader(path)
    store = reader.store().stream().collect()
    return {"course": course, "plan": plan, "events": events, "path": path, "store": store,
            "reader": reader, "recorder": recorder}


def column(store: ChunkStore, timeline: str, entity: str, component: str
           ) -> tuple[list[Any], list[Any]]:
    """(index values, component values) of every logged row of `entity` that has `component`
    and `timeline`, sorted by that timeline. Read chunk by chunk: the dataframe view would
    merge rows that share an index value."""
    rows: list[tuple[Any, Any]] = []
    for chunk in store.stream().filter(content=entity).to_chunks():
        batch = chunk.to_record_batch()
        if chunk.entity_path != entity or component not in batch.schema.names:
            continue
        if timeline not in batch.schema.names:
            continue
        rows += zip(batch.column(timeline).to_pylist(), batch.column(component).to_pylist(),
                    strict=True)
    rows = sorted((r for r in rows if r[0] is not None), key=lambda r: r[0])
    return [r[0] for r in rows], [r[1] for r in rows]


def static_value(store: ChunkStore, entity: str, component: str) -> Any:
    for chunk in store.stream().to_chunks():
        batch = chunk.to_record_batch()
        if chunk.entity_path == entity and chunk.is_static and component in batch.schema.names:
            return batch.column(component).to_pylist()[-1]
    raise AssertionError(f"no static {entity}:{component}")


def texts(store: ChunkStore, entity: str, component: str = "TextLog:text") -> list[str]:
    return [v[0] for v in column(store, "ride_time", entity, component)[1]]


def scalars(store: ChunkStore, timeline: str, entity: str) -> tuple[list[Any], np.ndarray]:
    index, values = column(store, timeline, entity, "Scalars:scalars")
    return index, np.array([v[0] for v in values])


def of_type(events: list[Any], kind: type) -> list[Any]:
    return [e for e in events if isinstance(e, kind)]


def test_file_has_recording_and_blueprint(ride: dict[str, Any]) -> None:
    reader: RrdReader = ride["reader"]
    [recording] = reader.recordings()
    assert recording.application_id == "itt_planner"
    assert recording.recording_id == "test-ride"
    # One layout, log_course's with the map zoomed to the course: with open_recording's
    # default as well, the web viewer showed that one (zoom 13) from the saved file.
    assert len(reader.blueprints()) == 1


def test_every_plotted_series_lies_under_a_panel_of_the_layout(ride: dict[str, Any]) -> None:
    """Each time-series entity of the recording is under one root of `PLOT_ROWS`, and the
    default layout has one view per root: a series logged elsewhere would be invisible."""
    roots = [panel.root for panels, _share in paths.PLOT_ROWS for panel in panels]
    series = {line.split()[0].lstrip("/") for line in ride["store"].summary().splitlines()
              if line.startswith(("/plots/", "/elevation/"))}
    assert series and all(any(s.startswith(f"{r}/") for r in roots) for s in series)
    plots = [v for v in views(default_blueprint().root_container)
             if isinstance(v, rrb.TimeSeriesView)]
    assert sorted(str(v.origin) for v in plots) == sorted(f"/{r}" for r in roots)


def views(item: Any) -> list[Any]:
    """The views of a blueprint container, depth first (a view has an origin)."""
    if hasattr(item, "origin"):
        return [item]
    return [v for child in item.contents for v in views(child)]


def test_actual_power_and_speed_equal_the_samples(ride: dict[str, Any]) -> None:
    power = of_type(ride["events"], PowerReading)
    index, values = scalars(ride["store"], "ride_time", "/plots/power/actual")
    assert len(values) == len(power)  # the NaN sample was skipped
    np.testing.assert_allclose(values, [p.power_w for p in power])
    stamps = [t.timestamp() for t in index]
    np.testing.assert_allclose(stamps, [p.stamp_s for p in power], atol=1e-6)
    speed = of_type(ride["events"], WheelSpeed)
    _, kmh = scalars(ride["store"], "ride_time", "/plots/speed_kmh/actual")
    np.testing.assert_allclose(kmh, [s.speed_mps * MPS_TO_KMH for s in speed])
    assert ride["recorder"].skipped_inputs == 2
    notes = texts(ride["store"], "/log/inputs")
    assert len(notes) == 1 and "non-finite" in notes[0]


def test_samples_are_placed_on_the_distance_timeline(ride: dict[str, Any]) -> None:
    """After the first state, power rows carry the rider's distance (monotone here)."""
    index, _ = scalars(ride["store"], "distance_m", "/plots/power/actual")
    # All but the first sample (logged before the first state at the same stamp).
    assert len(index) == len(of_type(ride["events"], PowerReading)) - 1
    assert index == sorted(index)
    assert index[0] >= 0 and index[-1] <= ride["course"].length_m + 1


def test_full_course_plan_curves_against_distance(ride: dict[str, Any]) -> None:
    plan = ride["plan"]
    store = ride["store"]
    for entity, field, scale in (
        ("/plots/power/plan", "pedal_power_w", 1.0),
        ("/plots/speed_kmh/plan", "v_mps", MPS_TO_KMH),
        ("/plots/w_prime_kj/plan", "w_prime_j", 1e-3),
        ("/plots/lean_deg/plan", "phi_rad", math.degrees(1.0)),
        ("/plots/friction_use/plan", "friction_use", 1.0),
    ):
        index, values = scalars(store, "distance_m", entity)
        assert len(values) == plan.n_nodes, entity
        np.testing.assert_allclose(index, np.round(plan.s_m))
        np.testing.assert_allclose(values, getattr(plan, field) * scale, err_msg=entity)
    index, _ = scalars(store, "distance_m", "/plots/power/critical")
    assert index == [0, round(ride["course"].length_m)]
    # Pedalling only: where the plan brakes (its power negative), the curve is at 0 W.
    _, pedal = scalars(store, "distance_m", "/plots/power/plan")
    assert plan.power_w.min() < -100.0 and pedal.min() == 0.0
    # The plan sampled at the rider on ride time: one row per 5 m step of the 1 Hz states.
    states = of_type(ride["events"], RiderState)
    _, at_rider = scalars(store, "ride_time", "/plots/speed_kmh/plan")
    assert len(at_rider) == len(states)
    np.testing.assert_allclose(at_rider, [plan.at("v_mps", s.s_m) * MPS_TO_KMH for s in states])
    # Lean in the corner is a real lean (the plan leans ~30 deg at R 30 m).
    _, lean = scalars(store, "distance_m", "/plots/lean_deg/plan")
    assert 20.0 < lean.max() < 45.0


def test_state_and_w_prime(ride: dict[str, Any]) -> None:
    states = of_type(ride["events"], RiderState)
    store = ride["store"]
    _, w = scalars(store, "ride_time", "/plots/w_prime_kj/actual")
    np.testing.assert_allclose(w, [s.w_prime_j / 1000 for s in states])
    for entity in ("/map/rider", "/world/rider"):
        comp = "GeoPoints:positions" if entity.startswith("/map") else "Points3D:positions"
        _, rows = column(store, "ride_time", entity, comp)
        assert len(rows) == len(states), entity
    _, pos = column(store, "ride_time", "/map/rider", "GeoPoints:positions")
    course = ride["course"]
    lat, lon = pos[-1][0]
    assert abs(lat - course.origin.lat_deg) < 0.01 and abs(lon - course.origin.lon_deg) < 0.01
    _, elev = scalars(store, "ride_time", "/elevation/rider")
    np.testing.assert_allclose(elev, [course.at("z_m", s.s_m) for s in states])
    _index, profile = scalars(store, "distance_m", "/elevation/profile")
    assert len(profile) == len(course.s_m)
    assert profile.max() == pytest.approx(course.z_m.max())


def test_advice_series_and_horizon_lines(ride: dict[str, Any]) -> None:
    advice = of_type(ride["events"], Advice)
    store = ride["store"]
    _, target = scalars(store, "ride_time", "/plots/power/target")
    np.testing.assert_allclose(target, [a.target_power_w for a in advice])
    _, cp = scalars(store, "ride_time", "/plots/power/critical")
    # The CP line is the CP in use each advice names (a refit shows as a step).
    np.testing.assert_allclose(cp, [a.cp_in_use_w for a in advice])
    assert set(cp) == {RIDER.critical_power_w, REFIT_CP_W}
    _, finish = scalars(store, "ride_time", "/plots/w_prime_kj/finish")
    np.testing.assert_allclose(finish, [a.w_prime_finish_j / 1000 for a in advice])
    # Solve times of the advice that came from a solve (on the plan, nothing is solved).
    _, solve = scalars(store, "ride_time", "/plots/solve_time_ms/replan")
    solved = [a.solve_time_s * 1000 for a in advice if a.solve_time_s > 0]
    assert 0 < len(solved) < len(advice)
    np.testing.assert_allclose(solve, solved)
    _, lines = column(store, "ride_time", "/map/target_line", "GeoLineStrings:line_strings")
    assert len(lines) == len(advice)
    assert all(2 <= len(line[0]) <= MAX_HORIZON_POINTS + 1 for line in lines)
    np.testing.assert_allclose(lines[0][0][0], [advice[0].line_lat_deg[0],
                                                advice[0].line_lon_deg[0]])
    _, strips = column(store, "ride_time", "/world/target_line", "LineStrips3D:strips")
    assert len(strips) == len(advice)


def test_text_log_has_advice_changes_and_diagnostic_changes(ride: dict[str, Any]) -> None:
    store = ride["store"]
    changes = texts(store, "/log/advice")
    # First advice, the +25 W step, fallback on and off again, and the climb's power rise.
    assert 4 <= len(changes) < len(of_type(ride["events"], Advice)) / 2
    assert any("FALLBACK" in t for t in changes)
    diag = texts(store, "/log/diagnostics")
    levels = texts(store, "/log/diagnostics", "TextLog:level")
    # solver ok -> overran -> ok, inputs ok once: 4 lines, not one per second.
    assert len(diag) == 4
    assert levels.count("WARN") == 1 and "overran" in diag[levels.index("WARN")]
    # The refit and the plan adoption the advice reports, once each.
    belief = texts(store, "/log/belief")
    assert len(belief) == 2
    assert f"{RIDER.critical_power_w:.0f} -> {REFIT_CP_W:.0f} W" in belief[0]
    assert "plan 1 adopted" in belief[1]


def test_refit_and_adoption_in_one_advice_are_both_logged(tmp_path: Path) -> None:
    """An advice whose CP in use and plan version both changed gives two belief lines."""
    course = make_course()
    plan = make_plan(course)
    path = tmp_path / "belief.rrd"
    rec = open_recording(RerunSink.parse(f"file:{path}"))
    recorder = RideRecorder(rec, course, RIDER, plan)
    for k, (cp, version) in enumerate([(RIDER.critical_power_w, 0), (REFIT_CP_W, 1)]):
        state = RiderState(T0_S + k, 100.0 + 10 * k, 0.0, 11.0, 0.0, 350.0, 20000.0, float(k))
        recorder.log_advice(make_advice(course, plan, state, cp_in_use_w=cp,
                                        plan_version=version))
    rec.flush()
    rec.disconnect()
    store = RrdReader(path).store().stream().collect()
    belief = texts(store, "/log/belief")
    assert len(belief) == 2
    assert f"{RIDER.critical_power_w:.0f} -> {REFIT_CP_W:.0f} W" in belief[0]
    assert "plan 1 adopted" in belief[1]
    assert texts(store, "/log/belief", "TextLog:level") == ["WARN", "INFO"]


def test_track_and_path_in_segments(ride: dict[str, Any]) -> None:
    store = ride["store"]
    fixes = of_type(ride["events"], GpsFix)
    n_segments = math.ceil((len(fixes) - 1) / (TRACK_SEGMENT - 1))
    summary = store.summary()
    segs = {line.split()[0] for line in summary.splitlines() if line.startswith("/map/track/")}
    assert len(segs) == n_segments
    _, last = column(store, "ride_time", "/map/track/seg_0000", "GeoLineStrings:line_strings")
    assert len(last) == min(TRACK_SEGMENT, len(fixes))
    assert len(last[-1][0]) == min(TRACK_SEGMENT, len(fixes))
    assert any(line.startswith("/world/path/seg_0000") for line in summary.splitlines())


def test_static_course_geometry(ride: dict[str, Any]) -> None:
    store = ride["store"]
    course = ride["course"]
    [line] = static_value(store, "/map/course", "GeoLineStrings:line_strings")
    assert len(line) == len(course.s_m)
    np.testing.assert_allclose(line[0], [course.origin.lat_deg, course.origin.lon_deg],
                               atol=1e-9)
    vertices = static_value(store, "/world/road", "Mesh3D:vertex_positions")
    assert len(vertices) == 2 * len(course.s_m)
    # Vertices alternate left / right edge: their distance is the road width.
    width = np.linalg.norm(np.subtract(vertices[0], vertices[1]))
    assert width == pytest.approx(course.width_left_m[0] + course.width_right_m[0], rel=1e-4)
    edges = static_value(store, "/world/road/edges", "LineStrips3D:strips")
    assert len(edges) == 2
    [plan_line] = static_value(store, "/map/plan_line", "GeoLineStrings:line_strings")
    assert len(plan_line) == ride["plan"].n_nodes


def test_small_on_disk(ride: dict[str, Any]) -> None:
    # ~1 minute of ride: the static part dominates; a full demo ride is measured in bench/.
    assert ride["path"].stat().st_size < 2_000_000


def test_recorder_without_plan_and_relative_stamps(tmp_path: Path) -> None:
    course = make_course()
    path = tmp_path / "noplan.rrd"
    rec = open_recording(RerunSink.parse(f"file:{path}"))
    recorder = RideRecorder(rec, course, RIDER, None)
    recorder.log_course()
    recorder.log_state(RiderState(3.0, 10.0, 0.5, 11.0, 0.0, 350.0, 20000.0, 3.0))
    recorder.log_sample(PowerReading(3.5, 351.0))
    recorder.log_diagnostics([Diagnostic(4.0, "inputs", Level.ERROR, "power stale")])
    rec.flush()
    rec.disconnect()
    store = RrdReader(path).store().stream().collect()
    index, values = scalars(store, "ride_time", "/plots/power/actual")
    assert values.tolist() == [351.0]
    assert index[0].total_seconds() == pytest.approx(3.5)  # a duration timeline
    assert "/plots/power/plan" not in store.summary()


def test_session_notes_are_static_warnings(tmp_path: Path) -> None:
    """The session's set-up warnings (the course's own air) reach a coach in Rerun at
    any time of the ride."""
    path = tmp_path / "notes.rrd"
    rec = open_recording(RerunSink.parse(f"file:{path}"))
    recorder = RideRecorder(rec, make_course(), RIDER, None)
    recorder.log_notes(["air 1.09 kg/m^3 at the course's altitude", "second note"])
    rec.flush()
    rec.disconnect()
    store = RrdReader(path).store().stream().collect()
    assert static_value(store, "/log/session", "TextLog:text") == [
        "air 1.09 kg/m^3 at the course's altitude\nsecond note"]
    assert static_value(store, "/log/session", "TextLog:level") == ["WARN"]


def test_sample_without_a_view_is_counted_and_noted_once(tmp_path: Path) -> None:
    """A sensor added to the inputs before the recorder has a view for it: not drawn,
    counted, one log/inputs line (not one per sample)."""
    @dataclass(frozen=True)
    class HeartRate:
        stamp_s: float
        bpm: float

    path = tmp_path / "hr.rrd"
    rec = open_recording(RerunSink.parse(f"file:{path}"))
    recorder = RideRecorder(rec, make_course(), RIDER, None)
    for t in (1.0, 2.0, 3.0):
        recorder.log_sample(HeartRate(t, 150.0))  # type: ignore[arg-type]
    recorder.log_sample(PowerReading(3.0, 300.0))
    rec.flush()
    rec.disconnect()
    store = RrdReader(path).store().stream().collect()
    assert recorder.skipped_inputs == 3
    assert texts(store, "/log/inputs") == ["HeartRate: no view for this sample type, not drawn"]
    assert scalars(store, "ride_time", "/plots/power/actual")[1].tolist() == [300.0]


@pytest.mark.parametrize(("text", "kind", "target"), [
    ("file:out/ride.rrd", "file", "out/ride.rrd"),
    ("spawn", "spawn", ""),
    ("connect", "connect", ""),
    ("connect:rerun+http://127.0.0.1:9876/proxy", "connect",
     "rerun+http://127.0.0.1:9876/proxy"),
    ("serve", "serve", ""),
    ("none", "none", ""),
])
def test_sink_parse(text: str, kind: str, target: str) -> None:
    sink = RerunSink.parse(text)
    assert (sink.kind, sink.target) == (kind, target)
    assert str(sink) == text
    assert sink.keeps_process_alive == (kind == "serve")


@pytest.mark.parametrize("text", ["", "file", "file:", "web", "spawn:x", "serve:1"])
def test_sink_parse_rejects(text: str) -> None:
    with pytest.raises(IttError, match="rerun sink"):
        RerunSink.parse(text)


def test_none_sink_records_nothing() -> None:
    rec = open_recording(RerunSink.parse("none"))
    assert not rr.is_enabled(rec)
    recorder = RideRecorder(rec, make_course(), RIDER, None)
    recorder.log_course()
    recorder.log_sample(PowerReading(1.0, 300.0))  # a no-op, no error
    assert isinstance(rec, rr.RecordingStream)


def test_one_stream_tees_to_several_sinks(tmp_path: Path) -> None:
    """Live viewer + review file from one stream: both sinks receive every row."""
    paths = [tmp_path / "a.rrd", tmp_path / "b.rrd"]
    rec = open_recording([RerunSink.parse(f"file:{p}") for p in paths])
    recorder = RideRecorder(rec, make_course(), RIDER, None)
    recorder.log_sample(PowerReading(2.0, 300.0))
    recorder.log_sample(PowerReading(3.0, 310.0))
    rec.flush()
    rec.disconnect()
    for path in paths:
        store = RrdReader(path).store().stream().collect()
        assert scalars(store, "ride_time", "/plots/power/actual")[1].tolist() == [300.0, 310.0]


def test_log_plan_draws_the_plan_in_force(tmp_path: Path) -> None:
    """An adopted plan (version 1) replaces the first plan's curves and ride-time samples;
    the same version again logs nothing."""
    course = make_course()
    first = make_plan(course)
    second = make_plan(course, ds_m=10.0)
    path = tmp_path / "adopt.rrd"
    rec = open_recording(RerunSink.parse(f"file:{path}"))
    recorder = RideRecorder(rec, course, RIDER, first)
    recorder.log_course()
    recorder.log_plan(second, 1)
    recorder.log_plan(second, 1)
    recorder.log_state(RiderState(T0_S, 50.0, 0.0, 11.0, 0.0, 350.0, 20000.0, 0.0))
    rec.flush()
    rec.disconnect()
    store = RrdReader(path).store().stream().collect()
    _, power = scalars(store, "distance_m", "/plots/power/plan")
    assert len(power) == first.n_nodes + second.n_nodes
    assert recorder.plan is second
