"""itt_msgs_py: one .msg definition for ROS and the core, CDR round trips, conversions."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap_ros2._dynamic import generate_dynamic
from support.messages import make_advice, make_advice_without_corner

import itt_msgs_py
from itt_msgs_py import convert, registry, topics
from itt_msgs_py.definitions import SEPARATOR, msg_texts, msgdef
from itt_planner.live.advice import Advice, Cue, Diagnostic, Level
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.model.state import RiderState

ROOT = Path(__file__).resolve().parents[2]
MSG_DIR = ROOT / "ros_ws" / "src" / "itt_msgs" / "msg"


def test_custom_types_come_from_the_ros_package_msg_files() -> None:
    # The Python package reads the ROS interface package's files: one definition.
    assert (ROOT / "itt_msgs_py" / "msg").resolve() == MSG_DIR.resolve()
    texts = msg_texts()
    assert set(texts) == {f"itt_msgs/msg/{p.stem}" for p in MSG_DIR.glob("*.msg")}
    for name, text in texts.items():
        assert text == (MSG_DIR / f"{name.rsplit('/', 1)[1]}.msg").read_text()
    cmake = (MSG_DIR.parent / "CMakeLists.txt").read_text()
    # Every .msg file is generated and none is listed twice: CMake globs msg/.
    glob = ('file(GLOB msg_files RELATIVE "${CMAKE_CURRENT_SOURCE_DIR}" '
            'CONFIGURE_DEPENDS "msg/*.msg")')
    assert glob in cmake
    assert "rosidl_generate_interfaces" in cmake
    assert 'format="3"' in (MSG_DIR.parent / "package.xml").read_text()


def test_schema_text_is_the_msg_file_plus_dependency_blocks() -> None:
    text = msgdef("itt_msgs/msg/Advice")
    blocks = text.split(f"{SEPARATOR}\n")
    assert blocks[0] == (MSG_DIR / "Advice.msg").read_text()
    headers = [b.splitlines()[0] for b in blocks[1:]]
    assert headers == ["MSG: std_msgs/Header", "MSG: builtin_interfaces/Time",
                       "MSG: itt_msgs/RiderState"]
    assert blocks[3] == "MSG: itt_msgs/RiderState\n" + (MSG_DIR / "RiderState.msg").read_text()
    # An independent parser (mcap_ros2's) accepts every schema we write.
    for topic in registry.TOPICS:
        assert topic.msgtype in generate_dynamic(topic.msgtype, msgdef(topic.msgtype))


def test_topic_names_and_qos() -> None:
    names = itt_msgs_py.topics_by_name()
    assert set(names) == {"/itt/gps/fix", "/itt/speed", "/itt/power", "/itt/target_power",
                          "/itt/target_line", "/itt/advice", "/diagnostics"}
    assert registry.GPS_FIX.name("/car2/itt/") == "/car2/itt/gps/fix"
    assert topics.DIAGNOSTICS.name("/car2") == "/diagnostics"
    assert registry.GPS_FIX.name("") == "/gps/fix"
    with pytest.raises(ValueError, match="bad token"):
        topics.normalize_namespace("/itt/2fast")
    for t in itt_msgs_py.INPUT_TOPICS:
        assert t.qos == topics.QoS(topics.Reliability.BEST_EFFORT, depth=5)
    for t in (topics.ADVICE, topics.TARGET_LINE, topics.TARGET_POWER, topics.DIAGNOSTICS):
        assert t.qos.reliability is topics.Reliability.RELIABLE and t.qos.depth == 10


def test_the_registry_has_one_entry_per_input_topic() -> None:
    """Each input topic has one entry (sample type, converters); nothing else is a sample."""
    entries = registry.SAMPLE_TOPICS
    assert [e.topic for e in entries] == list(registry.INPUT_TOPICS)
    assert [e.sample_type for e in entries] == [GpsFix, WheelSpeed, PowerReading]
    assert all(t.direction is topics.Direction.IN for t in registry.INPUT_TOPICS)
    assert not registry.is_sample(make_advice()) and not registry.is_sample(None)
    with pytest.raises(TypeError, match="not a registered input sample"):
        registry.sample_to_msg(make_advice())  # type: ignore[arg-type]


def test_prepare_codecs_does_each_topics_first_use_work_up_front() -> None:
    """Code, schema and offered QoS of every interface topic exist after `prepare_codecs`,
    so no message's first use generates them (the node's first advice did, holding up its
    inputs)."""
    from itt_msgs_py.definitions import typestore
    from itt_msgs_py.qos import offered_qos_yaml

    for topic in registry.TOPICS:  # as in a fresh process
        typestore.cache.pop(topic.msgtype, None)
    msgdef.cache_clear()
    offered_qos_yaml.cache_clear()
    registry.prepare_codecs()
    assert {t.msgtype for t in registry.TOPICS} <= set(typestore.cache)
    assert msgdef.cache_info().currsize >= len({t.msgtype for t in registry.TOPICS})
    assert offered_qos_yaml.cache_info().currsize == len({t.qos for t in registry.TOPICS})


def _roundtrip(msg: Any) -> Any:
    """The message through CDR bytes and back (a rosbags message object)."""
    data = itt_msgs_py.serialize(msg)
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR little-endian encapsulation header
    return itt_msgs_py.deserialize(data, type(msg).__msgtype__)


@pytest.mark.parametrize("sample", [
    GpsFix(1_700_000_000.5, 45.4384, 10.9916, 59.0, 3.0),
    GpsFix(1_700_000_000.0, -33.9, 151.2, math.nan),
    WheelSpeed(1_700_000_001.999999999, 13.75),
    PowerReading(1_700_000_002.25, 412.0, 92.0),
    PowerReading(12.0, 0.0),
])
def test_samples_round_trip_through_cdr(sample: object) -> None:
    topic, msg = registry.sample_to_msg(sample)  # type: ignore[arg-type]
    assert topic.msgtype == type(msg).__msgtype__
    assert registry.is_sample(sample)
    back = registry.to_core(topic, _roundtrip(msg))
    assert type(back) is type(sample)
    for name, value in vars(sample).items():
        got = getattr(back, name)
        if math.isnan(value):
            assert math.isnan(got)
        else:
            assert got == pytest.approx(value, abs=1e-6)


def test_stamps_keep_nanoseconds() -> None:
    t = convert.to_time(1_700_000_000.999_999_9999)
    assert (t.sec, t.nanosec) == (1_700_000_001, 0)
    assert convert.stamp_ns(1_700_000_000.25) == 1_700_000_000_250_000_000
    assert convert.from_time(convert.to_time(-0.5)) == -0.5


def test_advice_round_trip_and_derived_messages() -> None:
    advice = make_advice()
    back = convert.output_to_core(_roundtrip(convert.advice_to_msg(advice)))
    assert isinstance(back, Advice)
    for name in vars(advice):
        want, got = getattr(advice, name), getattr(back, name)
        if isinstance(want, np.ndarray):
            np.testing.assert_array_equal(got, want)
        elif isinstance(want, float):
            assert got == pytest.approx(want, abs=1e-6)
        else:
            assert got == want or isinstance(want, RiderState)
    assert back.state.gps_fresh is False and back.state.w_prime_j == 15_000.0

    tp = _roundtrip(convert.target_power_msg(advice))
    assert tp.power_w == 305.5 and tp.speed_mps == advice.horizon_speed_mps[0] and tp.fallback
    assert tp.cue == tp.CUE_BRAKE == Cue.BRAKE
    assert (tp.corner_speed_mps, tp.corner_distance_m) == (8.25, 87.5)
    # No corner ahead: NaN crosses the wire as NaN; the cue constants match the enum.
    none = convert.output_to_core(_roundtrip(convert.advice_to_msg(make_advice_without_corner())))
    assert isinstance(none, Advice)
    assert math.isnan(none.corner_speed_mps) and none.cue is Cue.PEDAL
    msg = convert.advice_to_msg(advice)
    assert {c.name: int(c) for c in Cue} == {n: getattr(msg, f"CUE_{n}") for n in Cue.__members__}

    path = _roundtrip(convert.target_line_msg(advice))
    assert path.header.frame_id == "map" and len(path.poses) == 25
    xyz = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                    for p in path.poses])
    np.testing.assert_allclose(xyz, np.c_[advice.line_x_m, advice.line_y_m, advice.line_z_m])
    # The line runs counter-clockwise on a circle: heading = polar angle + 90 degrees.
    q = path.poses[12].pose.orientation
    yaw = 2 * math.atan2(q.z, q.w)
    polar = math.atan2(advice.line_y_m[12], advice.line_x_m[12])
    assert math.remainder(yaw - polar - math.pi / 2, 2 * math.pi) == pytest.approx(0, abs=1e-3)
    assert q.x == q.y == 0.0 and q.z**2 + q.w**2 == pytest.approx(1.0)


def test_diagnostics_round_trip() -> None:
    diags = [Diagnostic(5.0, "itt/solver", Level.WARN, "slow", {"solve_time_s": "0.9"}),
             Diagnostic(5.0, "itt/gps", Level.OK, "fresh")]
    msg = _roundtrip(convert.diagnostics_to_msg(diags, 5.0))
    assert msg.status[0].hardware_id == "itt_planner"
    assert convert.output_to_core(msg) == diags


def test_wheel_contains_the_msg_files(tmp_path: Path) -> None:
    """A plain (non-editable) build ships the .msg files through the symlink.

    Built from a copy of the sources (symlink kept) so the checkout gets no build/ dir.
    """
    src = tmp_path / "src"
    for rel in ("itt_planner", "itt_msgs_py", "ros_ws/src/itt_msgs"):
        shutil.copytree(ROOT / rel, src / rel, symlinks=True,
                        ignore=shutil.ignore_patterns("__pycache__"))
    for rel in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / rel, src / rel)
    assert (src / "itt_msgs_py" / "msg").is_symlink()
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q",
                    "-w", str(tmp_path / "dist")], check=True, capture_output=True, timeout=300)
    wheel = next((tmp_path / "dist").glob("itt_planner-*.whl"))
    with zipfile.ZipFile(wheel) as zf:
        for p in MSG_DIR.glob("*.msg"):
            assert zf.read(f"itt_msgs_py/msg/{p.name}").decode() == p.read_text()
        assert "itt_msgs_py/fastdds_localhost.xml" in zf.namelist()  # the loopback profile
    # Installed from that wheel (no checkout on the path), the typestore finds the files.
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target",
                    str(site), str(wheel)], check=True, capture_output=True, timeout=300)
    probe = ("import itt_msgs_py, sys; assert itt_msgs_py.__file__.startswith(sys.argv[1]); "
             "print(sorted(n for n in itt_msgs_py.typestore.types if n.startswith('itt_msgs/')))")
    out = subprocess.run([sys.executable, "-c", probe, str(site)], check=True, text=True,
                         capture_output=True, cwd=tmp_path,
                         env={**os.environ, "PYTHONPATH": str(site)}, timeout=120).stdout
    assert out.strip() == str(sorted(f"itt_msgs/msg/{p.stem}" for p in MSG_DIR.glob("*.msg")))
    # The lazy packages' stubs ship too: without them their public names do not load.
    stubs = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "itt_planner").rglob("*.pyi"))
    assert stubs and set(stubs) <= set(zipfile.ZipFile(wheel).namelist())
    probe = ("import itt_planner, sys; assert itt_planner.__file__.startswith(sys.argv[1]); "
             "from itt_planner.calibration import calibrate; print(calibrate.__name__)")
    out = subprocess.run([sys.executable, "-c", probe, str(site)], check=True, text=True,
                         capture_output=True, cwd=tmp_path,
                         env={**os.environ, "PYTHONPATH": str(site)}, timeout=120).stdout
    assert out.strip() == "calibrate"
