"""The static report: HTML with embedded figures, PNG, and the `report` command.

Plans use the synthetic course; rides replay the demo bag (replanned every 20 s of ride
time against the 1D plan, solved into a temporary cache, without course re-solves: each
is a 3D solve of the rest of the course, and the report of adoptions is tested on a
trace of its own; this keeps the module quick).
"""

from __future__ import annotations

import base64
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure
from PIL import Image
from support.synthetic_ride import RIDER, make_course, make_plan
from typer.testing import CliRunner

from itt_planner.cli import app
from itt_planner.course.geometry import Course
from itt_planner.errors import IttError
from itt_planner.live.advice import Advice, Cue
from itt_planner.live.samples import PowerReading
from itt_planner.logs.ridelog import read_ride_log
from itt_planner.ocp.plan import Plan
from itt_planner.session.config import SessionConfig
from itt_planner.session.replay import replay_ride
from itt_planner.view.report import (
    draw_overview,
    render_html,
    ride_summary,
    rider_from_plan,
    summary,
    write_report,
)
from itt_planner.view.ride_report import RideTrace, belief_events, load_ride_trace

DEMO_BAG = Path(__file__).parents[2] / "bags" / "typical_verona-like.mcap"
#: (replay output, plan cache, ride duration) of the `replayed` fixture.
Replayed = tuple[Path, Path, float]


@pytest.fixture(scope="module")
def course() -> Course:
    return make_course()


@pytest.fixture(scope="module")
def plan(course: Course) -> Plan:
    return make_plan(course)


def embedded_images(page: str) -> list[Image.Image]:
    found = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    return [Image.open(io.BytesIO(base64.b64decode(b))) for b in found]


def test_html_is_self_contained_with_overview_and_corner(plan: Plan, course: Course) -> None:
    page = render_html(plan, course, RIDER)
    assert page.startswith("<!DOCTYPE html>") and "http" not in page  # nothing to fetch
    images = embedded_images(page)
    assert len(images) == 1 + len(course.corners)  # overview + the one corner
    for image in images:
        pixels = np.asarray(image.convert("L"), dtype=float)
        assert pixels.std() > 10  # figures, not blank canvases
    assert "critical power w" in page and "440" in page


def test_overview_power_is_pedalled(plan: Plan, course: Course) -> None:
    """The plan brakes into the corner (negative power at the contact point); the power
    panel draws what is pedalled, so its axis stays on the rider's 0-1 kW."""
    fig = Figure()
    draw_overview(fig, plan, course, RIDER)
    ax_power = fig.axes[0]
    drawn = ax_power.get_lines()[0].get_ydata()
    assert plan.power_w.min() < -1000.0 and np.min(drawn) == 0.0
    assert ax_power.get_ylim()[0] > -100.0


def test_summary_figures(plan: Plan, course: Course) -> None:
    table = summary(plan, course, RIDER)
    assert table["finish_time_s"] == pytest.approx(plan.finish_time_s, abs=0.01)
    assert table["average_speed_kmh"] == pytest.approx(course.length_m / plan.finish_time_s * 3.6,
                                                       abs=0.01)
    # Time-weighted average power lies between the plan's extremes.
    assert plan.power_w.min() < table["average_power_w"] < plan.power_w.max()
    assert 20 < table["max_lean_deg"] < 45


def test_png_report(plan: Plan, course: Course, tmp_path: Path) -> None:
    out = write_report(plan, course, tmp_path / "r.png", RIDER)
    image = Image.open(out)
    assert image.format == "PNG" and image.height > image.width  # overview above the corner


def test_report_rejects_wrong_course_and_suffix(plan: Plan, course: Course,
                                                tmp_path: Path) -> None:
    short = Course.from_centerline("short", np.linspace(0, 200, 201), np.zeros(201),
                                   np.zeros(201), origin=course.origin)
    with pytest.raises(IttError, match="wrong --course"):
        write_report(plan, short, tmp_path / "r.html")
    with pytest.raises(IttError, match=r"\.html or \.png"):
        write_report(plan, course, tmp_path / "r.pdf")


def test_rider_from_plan_header(plan: Plan) -> None:
    assert rider_from_plan(plan) is None  # the synthetic header names the rider only
    solved = Plan(**{**plan.__dict__, "meta": {"rider": RIDER.__dict__}})
    assert rider_from_plan(solved) == RIDER


def test_cli_report_html_json(plan: Plan, course: Course, tmp_path: Path) -> None:
    plan_path = plan.save(tmp_path / "p.plan.npz")
    course_path = course.save(tmp_path / "c.course.npz")
    out = tmp_path / "report.html"
    result = CliRunner().invoke(app, ["report", str(plan_path), "-o", str(out),
                                      "--course", str(course_path), "--json"])
    assert result.exit_code == 0, result.output
    payload = json.loads(result.stdout)
    assert payload["output"] == str(out) and payload["corners"] == 1
    assert len(embedded_images(out.read_text())) == 2


def test_cli_report_errors(plan: Plan, tmp_path: Path) -> None:
    plan_path = plan.save(tmp_path / "p.plan.npz")
    runner = CliRunner()
    # The plan names course 'synthetic-corner', which no loader knows.
    result = runner.invoke(app, ["report", str(plan_path), "-o", str(tmp_path / "r.html"),
                                 "--json"])
    assert result.exit_code == 1
    assert "synthetic-corner" in json.loads(result.stdout)["error"]


def test_demo_course_named_in_plan_header(tmp_path: Path) -> None:
    """A plan on the verona-like demo: the course is found from the plan's header."""
    from itt_planner.course.loader import load_course

    demo = load_course("verona-like")
    plan = make_plan(demo, ds_m=10.0)
    plan = Plan(**{**plan.__dict__, "meta": {"course": "verona-like"}})
    plan_path = plan.save(tmp_path / "v.plan.npz")
    out = tmp_path / "v.png"
    result = CliRunner().invoke(app, ["report", str(plan_path), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "verona-like" in result.stdout and Image.open(out).format == "PNG"


def belief_trace(course: Course, plan: Plan) -> RideTrace:
    """A ride of 20 advice over the synthetic course: CP refitted 440 -> 418 W at the
    8th advice, the re-solved plan 1 adopted at the 11th."""
    n = 20
    t = np.arange(n, dtype=float) * 2.0
    s = np.linspace(0.0, course.length_m, n)
    cp = np.where(np.arange(n) >= 7, 418.0, 440.0)
    version = np.where(np.arange(n) >= 10, 1, 0)
    power = np.interp(s, plan.s_m, plan.power_w)
    speed = np.interp(s, plan.s_m, plan.v_mps)
    lat, lon, _ = course.to_geodetic(*course.enu_at(s))
    return RideTrace(
        path=Path("synthetic.mcap"), start_stamp_s=0.0, end_stamp_s=float(t[-1]),
        power_t_s=t, power_w=power, power_s_m=s, speed_t_s=t, speed_mps=speed, speed_s_m=s,
        gps_lat_deg=np.asarray(lat), gps_lon_deg=np.asarray(lon), gps_s_m=s,
        advice_t_s=t, advice_s_m=s, advice_speed_mps=speed, target_power_w=power,
        w_prime_now_j=np.full(n, 20_000.0), w_prime_finish_j=np.full(n, 1_000.0),
        fallback=np.zeros(n, dtype=bool), solver_status=("converged",) * n, metadata={},
        cp_in_use_w=cp, plan_version=version, cue=np.zeros(n, dtype=int))


def test_ride_report_shows_refits_and_plan_adoptions(plan: Plan, course: Course) -> None:
    """The report of a ride names what the engine planned with (from the advice), not
    only the believed rider and the first plan: the table counts and lists the CP refit
    and the plan adoption, the figure steps the CP in use and marks both."""
    trace = belief_trace(course, plan)
    table = ride_summary(trace, plan, course, RIDER)
    assert (table["cp_refits"], table["plan_adoptions"]) == (1, 1)
    assert table["cp_in_use_end_w"] == 418.0
    km_refit, km_plan = trace.advice_s_m[7] / 1000, trace.advice_s_m[10] / 1000
    assert table["belief_changes"] == [
        f"CP in use 440 -> 418 W at {km_refit:.2f} km",
        f"plan 1 adopted at {km_plan:.2f} km (CP 418 W)",
    ]
    page = render_html(plan, course, RIDER, ride=trace)
    assert f"CP in use 440 -&gt; 418 W at {km_refit:.2f} km; plan 1 adopted" in page
    assert "cp refits</th><td>1<" in page and "plan adoptions</th><td>1<" in page
    # A ride without either says so.
    steady = RideTrace(**{**trace.__dict__, "cp_in_use_w": np.full(20, 440.0),
                          "plan_version": np.zeros(20, dtype=int)})
    table = ride_summary(steady, plan, course, RIDER)
    assert (table["cp_refits"], table["plan_adoptions"], table["belief_changes"]) == (0, 0, [])
    assert "belief changes</th><td>none<" in render_html(plan, course, RIDER, ride=steady)


def test_ride_report_without_a_power_meter(plan: Plan, course: Course) -> None:
    """A ride of GPS and speed only (which `replay` advises) gets its report: no power
    figures, the target and the plan drawn (it was refused: "no power samples")."""
    trace = belief_trace(course, plan)
    none = np.zeros(0)
    bare = RideTrace(**{**trace.__dict__, "power_t_s": none, "power_w": none,
                        "power_s_m": none})
    table = ride_summary(bare, plan, course, RIDER)
    assert table["average_power_w"] is None and table["max_power_w"] is None
    assert table["distance_km"] == pytest.approx(course.length_m / 1000, abs=0.01)
    page = render_html(plan, course, RIDER, ride=bare)
    assert len(embedded_images(page)) >= 1


@pytest.fixture(scope="module")
def replayed(tmp_path_factory: pytest.TempPathFactory) -> Replayed:
    """(replay output, plan cache, ride duration) of the typical rider's demo bag."""
    tmp = tmp_path_factory.mktemp("ride")
    out, cache = tmp / "replayed.mcap", tmp / "cache"
    config = SessionConfig(course="verona-like", rider="typical", model="1d",
                           replan_period_s=20.0, course_replan_period_s=0.0,
                           plan_cache=str(cache), deterministic=True)
    result = replay_ride(DEMO_BAG, config, output=out)
    assert result.errors == [] and result.advice_out > 50
    return out, cache, result.ride_duration_s


def test_ride_report_html_compares_the_ride_with_the_plan(replayed: Replayed, tmp_path: Path
                                                          ) -> None:
    log, cache, duration_s = replayed
    out = tmp_path / "ride.html"
    result = CliRunner().invoke(app, ["report", str(log), "-o", str(out), "--cache-dir",
                                      str(cache), "--json"])
    assert result.exit_code == 0, result.output
    table = json.loads(result.stdout)
    # Course, rider and model come from the replay's metadata.
    assert (table["course"], table["rider"], table["model"]) == ("verona-like", "typical", "1d")
    power = [p.power_w for topic, _, p in read_ride_log(log)
             if topic == "/itt/power" and isinstance(p, PowerReading)]
    assert table["average_power_w"] == pytest.approx(np.mean(power), abs=1.0)
    assert table["max_power_w"] == pytest.approx(max(power), abs=0.1)
    # The simulated rider stops logging at the finish line.
    assert table["finish_time_s"] == pytest.approx(duration_s, abs=5.0)
    assert table["finish_vs_plan_s"] == pytest.approx(
        table["finish_time_s"] - table["plan_finish_time_s"], abs=0.02)
    advice = [a for topic, _, a in read_ride_log(log)
              if topic == "/itt/advice" and isinstance(a, Advice)]
    assert table["advice"] == len(advice)
    assert table["fallbacks"] == sum(a.fallback for a in advice)
    assert sum(table["solver_status"].values()) == len(advice)
    page = out.read_text()
    assert "ride report" in page and "fallbacks" in page
    assert not re.search(r"(src|href)=[\"']?https?:", page)  # nothing to fetch
    images = embedded_images(page)
    assert len(images) == 1 + 3  # the ride overview + three corners with the GPS fixes
    for image in images:
        assert np.asarray(image.convert("L"), dtype=float).std() > 10


def test_ride_trace_places_samples_by_distance(replayed: Replayed) -> None:
    trace = load_ride_trace(replayed[0])
    assert trace.duration_s == pytest.approx(replayed[2])
    # Distance never runs backwards in time and covers the course (16.8 km).
    assert np.all(np.diff(trace.power_s_m) >= 0) and trace.power_s_m[-1] > 16_700
    assert len(trace.power_w) == len(trace.power_s_m) == len(trace.gps_s_m)
    assert trace.metadata["input"] == str(DEMO_BAG)
    # What the engine planned with comes from the advice: the typical rider's CP (no
    # refit on this nominal ride) and the first plan, cues pedal / coast / brake / climb.
    n = len(trace.advice_t_s)
    assert trace.cp_in_use_w.shape == trace.plan_version.shape == trace.cue.shape == (n,)
    events = belief_events(trace)
    assert sum(e.kind == "refit" for e in events) == int(np.sum(np.diff(trace.cp_in_use_w) != 0))
    assert sum(e.kind == "plan" for e in events) == int(np.sum(np.diff(trace.plan_version) != 0))
    assert set(np.unique(trace.cue)) <= {int(c) for c in Cue}


def test_ride_report_png(replayed: Replayed, tmp_path: Path) -> None:
    log, cache, _ = replayed
    out = tmp_path / "ride.png"
    result = CliRunner().invoke(app, ["report", str(log), "-o", str(out), "--cache-dir",
                                      str(cache)])
    assert result.exit_code == 0, result.output
    assert "fallbacks" in result.stdout
    image = Image.open(out)
    assert image.format == "PNG" and image.height > image.width


def test_raw_and_bad_logs_are_refused_by_name(tmp_path: Path) -> None:
    runner = CliRunner()
    out = str(tmp_path / "r.html")
    # A raw input log (no advice): it must be replayed first.
    result = runner.invoke(app, ["report", str(DEMO_BAG), "-o", out, "--json"])
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit)
    error = json.loads(result.stdout)["error"]
    assert str(DEMO_BAG) in error and "itt-planner replay" in error
    with pytest.raises(IttError, match="no advice"):
        load_ride_trace(DEMO_BAG)
    # Not an MCAP file at all.
    bogus = tmp_path / "ride.mcap"
    bogus.write_text("not a log")
    result = runner.invoke(app, ["report", str(bogus), "-o", out])
    assert result.exit_code == 1 and str(bogus) in result.output
    assert "Traceback" not in result.output
