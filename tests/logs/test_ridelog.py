"""MCAP ride logs: what we write, four independent readers read back; damage is survivable."""

from __future__ import annotations

import functools
import math
import random
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from support.mcap_readers import check_all_readers, rerun_value
from support.messages import make_advice

from itt_msgs_py import registry, topics
from itt_msgs_py.convert import stamp_ns
from itt_msgs_py.definitions import msgdef
from itt_planner.errors import RideLogError
from itt_planner.live.advice import Advice, Diagnostic, Level
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.logs.ridelog import RawRecord, RideLogReader, read_ride_log
from itt_planner.logs.ridelog_writer import RideLogWriter, RideMetadata

T0 = 1_700_000_000.0
STEPS = 300  # ~1 MB of messages: several 256 KiB chunks
#: What a log holds, in order: (topic, stamp, core value; None for types without one).
Written = list[tuple[str, float, object]]


def write_log(path: Path, steps: int = STEPS) -> list[tuple[str, float, object]]:
    """A synthetic ride log with every topic; returns what was written, in order."""
    written: list[tuple[str, float, object]] = []
    meta = RideMetadata(source="synthetic.fit", sha256="ab" * 32, device="test", rider="R")
    with RideLogWriter(path, metadata=meta) as w:
        for i in range(steps):
            t = T0 + i
            fix = GpsFix(t, 45.0 + 1e-4 * i, 11.0, 100.0 + i, 3.0)
            speed = WheelSpeed(t + 0.25, 10.0 + 0.01 * i)
            power = PowerReading(t + 0.5, 200.0 + i, math.nan if i % 2 else 90.0)
            for sample in (fix, speed, power):
                w.write_sample(sample)
            advice = make_advice(t + 0.75)
            w.write_advice(advice)
            diags = [Diagnostic(t + 0.75, "itt/solver", Level(i % 3), f"step {i}", {"i": str(i)})]
            w.write_diagnostics(diags, t + 0.75)
            written += [("/itt/gps/fix", t, fix), ("/itt/speed", t + 0.25, speed),
                        ("/itt/power", t + 0.5, power), ("/itt/advice", t + 0.75, advice),
                        ("/itt/target_power", t + 0.75, None),
                        ("/itt/target_line", t + 0.75, None), ("/diagnostics", t + 0.75, diags)]
    return written


@pytest.fixture(scope="module")
def ride_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Written]:
    path = tmp_path_factory.mktemp("log") / "ride.mcap"
    return path, write_log(path)


def assert_same(read: list[tuple[str, float, object]], written: Written) -> None:
    assert [(t, round(s, 6)) for t, s, _ in read] == [(t, round(s, 6)) for t, s, _ in written]
    for (_, _, got), (_, _, want) in zip(read, written, strict=True):
        if want is None:
            continue
        if isinstance(want, Advice):
            assert isinstance(got, Advice)
            np.testing.assert_array_equal(got.horizon_power_w, want.horizon_power_w)
            assert got.state == want.state and got.solver_status == want.solver_status
        elif isinstance(want, list):
            assert got == want
        else:
            assert type(got) is type(want)
            for name, value in vars(want).items():
                g = getattr(got, name)
                assert (math.isnan(g) and math.isnan(value)) or g == pytest.approx(value, abs=1e-6)


def test_round_trip_and_metadata(ride_log: tuple[Path, Written]) -> None:
    path, written = ride_log
    reader = RideLogReader(path)
    assert_same(list(reader), written)
    assert reader.metadata["itt_ride"] == {"source": "synthetic.fit", "sha256": "ab" * 32,
                                           "device": "test", "rider": "R"}
    assert reader.errors == [] and reader.warnings == []
    with path.open("rb") as f:
        mcap = make_reader(f)
        assert mcap.get_header().profile == "ros2"
        for schema, _channel, msg in mcap.iter_messages():
            assert schema is not None
            assert msg.log_time == msg.publish_time  # = the header stamp
            assert schema.data.decode() == msgdef(schema.name)
        assert {m.name for m in mcap.iter_metadata()} == {"itt_ride"}


def test_four_readers_agree(ride_log: tuple[Path, Written], tmp_path: Path) -> None:
    path, _ = ride_log
    expected = {t.name(): (t.msgtype, STEPS) for t in registry.TOPICS}
    got = check_all_readers(path, expected, tmp_path)
    i = 7
    lat = 45.0 + 1e-4 * i
    assert got["mcap_ros2"]["/itt/gps/fix"][i].latitude == pytest.approx(lat)
    assert got["rosbags"]["/itt/gps/fix"][i].latitude == pytest.approx(lat)
    assert rerun_value(got["rerun"]["/itt/gps/fix"][i])["lat_lon"] == pytest.approx([lat, 11.0])
    want = make_advice(T0 + i + 0.75)
    for adv in (got["mcap_ros2"]["/itt/advice"][i], got["rosbags"]["/itt/advice"][i],
                rerun_value(got["rerun"]["/itt/advice"][i])):
        get: Callable[[str], Any] = (adv.get if isinstance(adv, dict)
                                     else functools.partial(getattr, adv))
        np.testing.assert_allclose(list(get("power_w")), want.horizon_power_w)
        assert get("solver_status") == "Solve_Succeeded" and get("fallback") is True
        state = get("state")
        assert (state["w_prime_j"] if isinstance(state, dict) else state.w_prime_j) == 15_000.0
    for power in (got["mcap_ros2"]["/itt/power"][i], got["rosbags"]["/itt/power"][i]):
        assert power.power_w == 207.0 and math.isnan(power.cadence_rpm)
    assert rerun_value(got["rerun"]["/itt/power"][i])["power_w"] == 207.0
    assert len(rerun_value(got["rerun"]["/itt/target_line"][i])["poses"]) == 25
    assert rerun_value(got["rerun"]["/diagnostics"][i])["status"][0]["level"] == i % 3
    assert got["rosbags"]["/diagnostics"][i].status[0].name == "itt/solver"


def test_channels_carry_the_offered_qos_rosbag2_replays(ride_log: tuple[Path, Written],
                                                        tmp_path: Path) -> None:
    """`offered_qos_profiles` (required by the MCAP ros2 profile) as rosbags reads it:
    sensors best-effort keep-last 5, outputs reliable; a raw copy keeps the source's."""
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import ConnectionExtRosbag2, QosHistory, QosReliability

    path, _ = ride_log
    copy = tmp_path / "copy.mcap"
    with RideLogWriter(copy) as w:
        for record in RideLogReader(path).records():
            w.write_raw(record._replace(topic=record.topic.replace("/itt/", "/other/")))
    for log, prefix in ((path, "/itt/"), (copy, "/other/")):
        with AnyReader([log]) as reader:
            qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections
                   if isinstance(c.ext, ConnectionExtRosbag2)}
        for topic in registry.TOPICS:
            name = topic.name().replace("/itt/", prefix)
            (profile,) = qos[name]
            want = (QosReliability.BEST_EFFORT if topic.direction is topics.Direction.IN
                    else QosReliability.RELIABLE)
            assert profile.reliability is want, name
            assert profile.history is QosHistory.KEEP_LAST and profile.depth == topic.qos.depth


def test_truncated_at_random_bytes_yields_everything_before(ride_log: tuple[Path, Written],
                                                            tmp_path: Path) -> None:
    path, written = ride_log
    data = path.read_bytes()
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    last_chunk = summary.chunk_indexes[-1]
    data_end = last_chunk.chunk_start_offset + last_chunk.chunk_length
    rng = random.Random(5)
    cut_path = tmp_path / "cut.mcap"
    counts = []
    for cut in sorted(rng.randrange(100, data_end) for _ in range(6)):
        cut_path.write_bytes(data[:cut])
        read: Written = []
        with pytest.raises(RideLogError, match=r"cut\.mcap: truncated.* after \d+ messages"):
            read.extend(read_ride_log(cut_path))
        assert_same(read, written[: len(read)])
        counts.append(len(read))
    assert counts == sorted(counts) and 0 < counts[-1] < len(written)
    # Cut inside the summary section: every message is there, only a warning.
    cut_path.write_bytes(data[:-50])
    reader = RideLogReader(cut_path)
    assert len(list(reader)) == len(written) and "summary" in reader.warnings[0]


def test_corrupted_chunk_loses_only_that_chunk(ride_log: tuple[Path, Written],
                                               tmp_path: Path) -> None:
    path, written = ride_log
    data = bytearray(path.read_bytes())
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = summary.chunk_indexes
    assert len(chunks) >= 3
    for victim in (chunks[0], chunks[1]):  # the first chunk also holds the channel records
        bad = bytearray(data)
        middle = victim.chunk_start_offset + victim.chunk_length // 2
        bad[middle:middle + 8] = bytes(b ^ 0x5A for b in bad[middle:middle + 8])
        bad_path = tmp_path / "bad.mcap"
        bad_path.write_bytes(bad)
        reader = RideLogReader(bad_path)
        read: Written = []
        with pytest.raises(RideLogError, match=r"bad\.mcap: corrupted chunk at byte"):
            read.extend(reader)
        # Exactly one contiguous run of messages is gone: the chunk's.
        n_lost = len(written) - len(read)
        first = next(i for i, (r, w) in enumerate(zip(read, written, strict=False))
                     if (r[0], round(r[1], 6)) != (w[0], round(w[1], 6)))
        assert 0 < n_lost < len(written) / 2
        assert_same(read, written[:first] + written[first + n_lost:])
        assert victim.message_start_time <= stamp_ns(written[first][1])


def test_crash_leaves_a_readable_file(tmp_path: Path) -> None:
    """A process killed while writing leaves every finished chunk readable."""
    path = tmp_path / "crash.mcap"
    script = (
        "import os, sys; sys.path[:0] = [sys.argv[2], sys.argv[3]]\n"
        "from test_ridelog import write_log\n"
        "from itt_planner.logs import ridelog_writer\n"
        "ridelog_writer.RideLogWriter.close = lambda self: os._exit(3)  # die before the summary\n"
        "write_log(__import__('pathlib').Path(sys.argv[1]))\n")
    proc = subprocess.run([sys.executable, "-c", script, str(path), str(Path(__file__).parent),
                           str(Path(__file__).parents[1])],
                          capture_output=True, timeout=120, check=False)
    assert proc.returncode == 3
    read: Written = []
    with pytest.raises(RideLogError, match="truncated"):
        read.extend(read_ride_log(path))
    assert len(read) > STEPS  # the finished chunks: most of the ride


def test_exception_inside_with_still_finishes_the_file(tmp_path: Path) -> None:
    path = tmp_path / "err.mcap"
    # The exception must leave the writer's `with` (PT012: two statements on purpose).
    with pytest.raises(ZeroDivisionError), RideLogWriter(path) as w:  # noqa: PT012
        w.write_sample(WheelSpeed(T0, 5.0))
        _ = 1 / 0
    reader = RideLogReader(path)
    assert [v for _, _, v in reader] == [WheelSpeed(T0, 5.0)]
    assert reader.errors == reader.warnings == []


def test_unknown_topics_are_skipped_and_counted(tmp_path: Path,
                                                caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "extra.mcap"
    string_def = msgdef("std_msgs/msg/String").encode()
    with RideLogWriter(path) as w:
        for i in range(3):
            w.write_sample(PowerReading(T0 + i, 100.0))
            w.write_raw(RawRecord("/tf_static", "std_msgs/msg/String", "ros2msg", string_def,
                                  "cdr", stamp_ns(T0 + i), stamp_ns(T0 + i),
                                  b"\x00\x01\x00\x00\x02\x00\x00\x00x\x00"))
    reader = RideLogReader(path)
    assert [t for t, _, _ in reader] == ["/itt/power"] * 3
    assert reader.skipped == {"/tf_static": 3}
    assert reader.warnings == ["skipped 3 messages of unknown topic /tf_static"]
    assert "unknown topic /tf_static" in caplog.text


def test_known_topic_with_wrong_type_is_an_error_naming_it(tmp_path: Path) -> None:
    path = tmp_path / "wrong.mcap"
    with RideLogWriter(path) as w:
        w.write_sample(GpsFix(T0, 45.0, 11.0, 0.0))
        # A wheel speed published on the power topic.
        w.write_msg(topics.Topic("power", "geometry_msgs/msg/TwistStamped", topics.SENSOR_QOS,
                                 topics.Direction.IN),
                    registry.wheel_speed_to_msg(
                        WheelSpeed(T0, 3.0)))
        w.write_sample(WheelSpeed(T0 + 1, 4.0))
    read: Written = []
    with pytest.raises(RideLogError, match=r"wrong.mcap: topic /itt/power has type "
                                           r"geometry_msgs/msg/TwistStamped.*expected "
                                           r"itt_msgs/msg/PowerStamped"):
        read.extend(read_ride_log(path))
    assert [t for t, _, _ in read] == ["/itt/gps/fix", "/itt/speed"]


def test_not_an_mcap_file(tmp_path: Path) -> None:
    path = tmp_path / "ride.fit"
    path.write_bytes(b"\x0e\x10garbage" * 100)
    with pytest.raises(RideLogError, match=r"ride\.fit: not an MCAP file"):
        list(read_ride_log(path))
    with pytest.raises(RideLogError, match="cannot open"):
        list(read_ride_log(tmp_path / "missing.mcap"))
