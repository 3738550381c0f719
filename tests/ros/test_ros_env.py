"""Real ROS 2 from the venv: loopback-only Fast DDS between plain rclpy processes, and the
`itt_msgs` classes rosidl built agreeing with what `itt_msgs_py` reads from the same .msg
files, down to the same CDR bytes in both directions (up to padding, see _assert_same_cdr).

Skipped, with set-up's one-line reason, where the ROS 2 wheels are not installed.
"""

from __future__ import annotations

import importlib
import ipaddress
import json
import queue
import subprocess
import sys
import textwrap
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import psutil
import pytest
from rosbags.interfaces import Nodetype
from support.messages import make_advice

from itt_msgs_py import convert, deserialize, registry, serialize, typestore
from itt_msgs_py.dds_env import profile_path
from itt_planner.live.advice import Diagnostic, Level
from itt_planner.live.samples import GpsFix, PowerReading, WheelSpeed

TOPIC = "/itt_test/fix"
# Plain rclpy on both sides: nothing of the project in these processes.
TALKER = f"""
import rclpy
from rclpy.executors import ExternalShutdownException
from sensor_msgs.msg import NavSatFix

rclpy.init()
node = rclpy.create_node("talker")
pub = node.create_publisher(NavSatFix, "{TOPIC}", 10)
count = 0

def tick():
    global count
    count += 1
    msg = NavSatFix(latitude=45.438, longitude=10.99 + count * 1e-6, altitude=59.0)
    msg.header.frame_id = "gps"
    pub.publish(msg)

node.create_timer(0.05, tick)
try:
    rclpy.spin(node)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
"""
LISTENER = f"""
import json
import rclpy
from rclpy.executors import ExternalShutdownException
from sensor_msgs.msg import NavSatFix

rclpy.init()
node = rclpy.create_node("listener")

def on_fix(msg):
    print(json.dumps({{"lat": msg.latitude, "lon": msg.longitude, "frame": msg.header.frame_id}}),
          flush=True)

node.create_subscription(NavSatFix, "{TOPIC}", on_fix, 10)
try:
    rclpy.spin(node)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
"""


def _lines(proc: subprocess.Popen[str]) -> queue.Queue[str]:
    """The process's stdout lines, read on a thread so the test can wait with a timeout."""
    lines: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.put(line)

    threading.Thread(target=pump, daemon=True).start()
    return lines


def _non_loopback_sockets(pid: int) -> list[str]:
    """Every IPv4/IPv6 socket of `pid` whose local or remote address is not loopback."""
    bad: list[str] = []
    for conn in psutil.Process(pid).net_connections(kind="inet"):
        remote: Any = conn.raddr  # an empty tuple when unconnected, whatever the stubs say
        bad.extend(f"{conn.type.name} {conn.laddr} -> {remote or '-'}"
                   for addr in (conn.laddr, remote)
                   if addr and not ipaddress.ip_address(addr.ip).is_loopback)
    return bad


def test_two_rclpy_processes_talk_over_loopback_only(
        ros_env: dict[str, str], tmp_path: Path) -> None:
    assert ros_env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(profile_path())
    procs = []
    try:
        for name, code in (("listener", LISTENER), ("talker", TALKER)):
            script = tmp_path / f"{name}.py"
            script.write_text(textwrap.dedent(code))
            procs.append(subprocess.Popen(
                [sys.executable, str(script)], env=ros_env, cwd=tmp_path, text=True,
                stdout=subprocess.PIPE, stderr=subprocess.PIPE))
        listener, _talker = procs
        received = _lines(listener)
        fixes: list[Any] = []
        while len(fixes) < 5:
            try:
                fixes.append(json.loads(received.get(timeout=30.0)))
            except queue.Empty:
                pytest.fail("the listener received no NavSatFix within 30 s: " + "".join(
                    p.stderr.read() if p.poll() is not None and p.stderr else "" for p in procs))
        assert all(f["lat"] == 45.438 and f["frame"] == "gps" for f in fixes)
        lons = [f["lon"] for f in fixes]
        assert lons == sorted(lons) and len(set(lons)) == len(lons)  # in order, no repeats
        # Both participants are up and matched: every socket they hold is on loopback.
        for proc in procs:
            assert psutil.Process(proc.pid).net_connections(kind="inet"), "no sockets at all?"
            assert _non_loopback_sockets(proc.pid) == []
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:  # a loaded machine can take long to tear down a participant
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)


# --- the generated classes against the rosbags typestore --------------------------------

ITT_TYPES = ["Advice", "RiderState", "PowerStamped", "TargetPower"]
# rosbags base type names -> the rosidl names rclpy reports.
ROSIDL_BASE = {"float64": "double", "float32": "float", "bool": "boolean", "string": "string",
               "int32": "int32", "uint32": "uint32", "int8": "int8", "uint8": "uint8"}


def _rosidl_type_name(kind: Nodetype, spec: Any) -> str:
    """rclpy's `get_fields_and_field_types()` spelling of a rosbags field type."""
    if kind == Nodetype.BASE:
        return ROSIDL_BASE[spec[0]]
    if kind == Nodetype.NAME:
        package, _, name = spec.split("/")
        return f"{package}/{name}"
    if kind == Nodetype.SEQUENCE:
        (inner_kind, inner_spec), bound = spec
        assert bound == 0, "bounded sequences are not used by itt_msgs"
        return f"sequence<{_rosidl_type_name(inner_kind, inner_spec)}>"
    raise AssertionError(f"field kind {kind} not used by itt_msgs")


def _ros_class(msgtype: str) -> Any:
    """The rclpy (rosidl-generated) class of a message type."""
    package, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


@pytest.mark.usefixtures("requires_ros")
@pytest.mark.parametrize("name", ITT_TYPES)
def test_generated_class_has_the_fields_of_the_msg_file(name: str) -> None:
    _, fields = typestore.fielddefs[f"itt_msgs/msg/{name}"]
    expected = {field: _rosidl_type_name(kind, spec) for field, (kind, spec) in fields}
    cls = _ros_class(f"itt_msgs/msg/{name}")
    assert cls.get_fields_and_field_types() == expected
    assert list(cls.get_fields_and_field_types()) == [field for field, _ in fields]  # order


def _plain(msg: Any) -> Any:
    """Nested dicts and lists of Python values, for a rosbags or an rclpy message alike."""
    if hasattr(type(msg), "get_fields_and_field_types"):
        return {f: _plain(getattr(msg, f)) for f in type(msg).get_fields_and_field_types()}
    if hasattr(msg, "__msgtype__"):  # rosbags: its dataclass fields include the constants
        _, fields = typestore.fielddefs[msg.__msgtype__]
        return {f: _plain(getattr(msg, f)) for f, _ in fields}
    if isinstance(msg, (list, tuple, np.ndarray)) or type(msg).__name__ == "array":
        return [_plain(v) for v in msg]
    if isinstance(msg, bytes) and len(msg) == 1:  # rclpy's `byte` field; rosbags: an int
        return msg[0]
    return msg.item() if isinstance(msg, np.generic) else msg


def _ros_message(cls: Any, plain: dict[str, Any]) -> Any:
    """An rclpy message of `cls` set field by field from `_plain` values (no CDR involved)."""
    from rosidl_parser.definition import AbstractNestedType, BasicType, NamespacedType

    def ros_type(slot: NamespacedType) -> Any:
        return getattr(importlib.import_module(".".join(slot.namespaces)), slot.name)

    msg = cls()
    for field, slot in zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES, strict=True):
        value = plain[field]
        if isinstance(slot, NamespacedType):
            value = _ros_message(ros_type(slot), value)
        elif (isinstance(slot, AbstractNestedType)
              and isinstance(slot.value_type, NamespacedType)):
            value = [_ros_message(ros_type(slot.value_type), v) for v in value]
        elif isinstance(slot, BasicType) and slot.typename == "octet":
            value = bytes([value])
        setattr(msg, field, value)
    return msg


_ADVICE = make_advice(n=7)
# What the node publishes and subscribes, made by the same conversions it uses.
MESSAGES: dict[str, Callable[[], Any]] = {
    "itt_msgs/msg/Advice": lambda: convert.advice_to_msg(_ADVICE),
    "itt_msgs/msg/RiderState": lambda: convert.state_to_msg(_ADVICE.state),
    "itt_msgs/msg/TargetPower": lambda: convert.target_power_msg(_ADVICE),
    "itt_msgs/msg/PowerStamped": lambda: registry.power_reading_to_msg(
        PowerReading(stamp_s=1_700_000_000.123456789, power_w=312.5, cadence_rpm=91.0)),
    "sensor_msgs/msg/NavSatFix": lambda: registry.gps_fix_to_msg(
        GpsFix(stamp_s=1_700_000_001.5, lat_deg=45.438, lon_deg=10.99, alt_m=59.0, std_m=2.5)),
    "geometry_msgs/msg/TwistStamped": lambda: registry.wheel_speed_to_msg(
        WheelSpeed(stamp_s=1_700_000_002.25, speed_mps=13.4)),
    "nav_msgs/msg/Path": lambda: convert.target_line_msg(_ADVICE),
    "diagnostic_msgs/msg/DiagnosticArray": lambda: convert.diagnostics_to_msg(
        [Diagnostic(stamp_s=1_700_000_003.0, name="itt/solver", level=Level.WARN,
                    message="fallback plan in use", values={"fallbacks": "2"})],
        1_700_000_003.0),
}


def _assert_same_cdr(ours: bytes, theirs: bytes, msgtype: str) -> None:
    """rclpy's CDR equals ours byte for byte except where CDR has padding: Fast CDR leaves
    alignment gaps as they were in its (uninitialized) buffer and pads the payload to a
    multiple of 4, where rosbags writes zeros and stops at the last field. So: every byte
    that differs is a zero of ours, at most 3 bytes are appended, and our codec turns
    rclpy's bytes back into exactly ours."""
    assert 0 <= len(theirs) - len(ours) <= 3
    assert all(a == 0 for a, b in zip(ours, theirs, strict=False) if a != b)
    assert serialize(deserialize(theirs, msgtype)) == ours


@pytest.mark.usefixtures("requires_ros")
@pytest.mark.parametrize("msgtype", list(MESSAGES))
def test_cdr_is_the_same_between_rclpy_and_itt_msgs_py(msgtype: str) -> None:
    from rclpy.serialization import deserialize_message, serialize_message

    ours = MESSAGES[msgtype]()
    assert ours.__msgtype__ == msgtype
    cdr = serialize(ours)
    cls = _ros_class(msgtype)
    # itt_msgs_py -> rclpy: rclpy reads our bytes to the same values and writes them back.
    theirs = deserialize_message(cdr, cls)
    assert _plain(theirs) == _plain(ours)
    _assert_same_cdr(cdr, serialize_message(theirs), msgtype)
    # rclpy -> itt_msgs_py: a message rclpy built field by field (no CDR involved) and
    # serialized reads back with our codec to the same values.
    their_cdr = serialize_message(_ros_message(cls, _plain(ours)))
    _assert_same_cdr(cdr, their_cdr, msgtype)
    assert _plain(deserialize(their_cdr, msgtype)) == _plain(ours)
