"""The demo ride logs in bags/: small, labelled SIMULATED, readable, and replayable."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest
from mcap.reader import make_reader

from itt_planner.live.advice import Advice
from itt_planner.live.course_replan import CourseReplanSettings
from itt_planner.live.engine import ON_PLAN
from itt_planner.logs.ridelog import METADATA_NAME, read_ride_log
from itt_planner.session.config import SessionConfig
from itt_planner.session.replay import replay_ride

BAGS = Path(__file__).resolve().parents[2] / "bags"
DEMO = {  # bag -> (course, rider)
    "typical_verona-like.mcap": ("verona-like", "typical"),
    "specialist_verona-like.mcap": ("verona-like", "specialist"),
    "climber_verona-like.mcap": ("verona-like", "climber"),
    "typical_rovereto-like.mcap": ("rovereto-like", "typical"),
    "typical_verona-like_cp-overestimated.mcap": ("verona-like", "typical"),
}


def _stamps(path: Path, topic: str) -> list[float]:
    return [stamp for name, stamp, _ in read_ride_log(path) if name == topic]


@pytest.mark.parametrize("name", sorted(DEMO))
def test_demo_bag_is_small_simulated_and_complete(name: str) -> None:
    path = BAGS / name
    assert path.stat().st_size <= 5 * 1024 * 1024
    with path.open("rb") as fh:
        reader = make_reader(fh)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        summary = reader.get_summary()
        assert summary is not None
        channels = summary.channels.values()
        # Sensors offered best-effort, as ros2 bag play must offer them again.
        assert all("reliability: best_effort" in c.metadata["offered_qos_profiles"]
                   for c in channels)
    assert "SIMULATED" in meta[METADATA_NAME]["source"]
    assert meta[METADATA_NAME]["rider"] == DEMO[name][1]
    topics: dict[str, list[float]] = {}
    for topic, stamp, sample in read_ride_log(path):
        assert sample is not None
        topics.setdefault(topic, []).append(stamp)
    assert set(topics) == {"/itt/gps/fix", "/itt/speed", "/itt/power"}
    duration = max(topics["/itt/gps/fix"]) - min(topics["/itt/gps/fix"])
    assert duration > 15 * 60  # a whole time trial, not a snippet
    for stamps in topics.values():  # 1 Hz sensors, no gaps
        assert len(stamps) >= duration
        assert max(b - a for a, b in itertools.pairwise(stamps)) <= 1.5


def _assert_advice_covers_ride(out: Path, bag: Path, period_s: float) -> None:
    fixes = _stamps(bag, "/itt/gps/fix")
    advice = _stamps(out, "/itt/advice")
    assert advice[0] - fixes[0] <= 2 * period_s + 5
    assert fixes[-1] - advice[-1] <= 2 * period_s + 5
    assert max(b - a for a, b in itertools.pairwise(advice)) <= 2 * period_s


@pytest.mark.slow  # 35 s (two re-solves of the rest of the course); `make test` runs
# the engine's re-solve (tests/live/test_engine.py) and the replay (tests/session/) apart.
def test_make_demo_bag_replays_with_advice_for_the_whole_ride(tmp_path: Path) -> None:
    """The `make demo` bag (the rider's CP 5 % below the planner's belief), replanned
    every 10 s of ride time against the 1D plan to keep the suite quick (the 3D plan of
    `make demo` is a minute's solve; the horizon and the course re-solves are 3D in
    both): the plan is advised while the rider keeps to it, then the engine sees the
    rider run dry, refits CP and replans with the horizon until the rest of the course,
    re-solved for the refitted CP, is the plan advised (`course_replan`, 15 s of ride
    time later)."""
    bag = BAGS / "typical_verona-like_cp-overestimated.mcap"
    config = SessionConfig(course="verona-like", rider="typical", model="1d",
                           replan_period_s=10.0, plan_cache=str(tmp_path / "cache"),
                           deterministic=True)
    result = replay_ride(bag, config, output=tmp_path / "advice.mcap")
    assert not result.errors
    assert result.advice_out >= result.ride_duration_s / 10 - 2
    _assert_advice_covers_ride(tmp_path / "advice.mcap", bag, 10.0)
    statuses = [a.solver_status for name, _, a in read_ride_log(tmp_path / "advice.mcap")
                if name == "/itt/advice" and isinstance(a, Advice)]
    assert statuses[0] == ON_PLAN
    first_solve = next(i for i, st in enumerate(statuses) if st != ON_PLAN)
    assert first_solve > len(statuses) / 4  # on the plan until the rider runs dry
    back = next(i for i in range(first_solve, len(statuses)) if statuses[i] == ON_PLAN)
    # The horizon until the re-solve is due (`delay_s`, 15 s: the next 10 s advice after).
    assert back - first_solve == math.ceil(CourseReplanSettings().delay_s / 10.0)
    assert all(st.startswith("Solve") for st in statuses[first_solve:back])
    assert statuses.count(ON_PLAN) > 0.9 * len(statuses)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(DEMO))
def test_every_demo_bag_replays_deterministically_at_1_hz(name: str, tmp_path: Path) -> None:
    bag = BAGS / name
    course, rider = DEMO[name]
    payloads = []
    for run in ("a", "b"):
        out = tmp_path / f"{run}.mcap"
        config = SessionConfig(course=course, rider=rider, plan_cache=str(tmp_path / "cache"),
                               deterministic=True)
        result = replay_ride(bag, config, output=out)
        assert not result.errors
        _assert_advice_covers_ride(out, bag, 1.0)
        with out.open("rb") as fh:
            payloads.append([m.data for _, c, m in make_reader(fh).iter_messages()
                             if c.topic == "/itt/advice"])
    assert payloads[0] == payloads[1]
