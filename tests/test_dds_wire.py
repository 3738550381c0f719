"""ROS 2 wire conventions of the DDS layer: names, types, QoS and CDR bytes.

The reference for the bytes is `rosbags` (what ROS 2 bags hold); the reference for
the type description is Cyclone itself: a typed Cyclone endpoint built from our IDL
struct must read our raw bytes and write the same bytes.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import DDSException
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy
from cyclonedds.sub import DataReader
from dds_support import RIDE_T0_S, random_domain

from itt_msgs_py import TOPICS, serialize, topics, typestore
from itt_msgs_py.convert import (
    advice_to_msg,
    diagnostics_to_msg,
    gps_fix_to_msg,
    power_reading_to_msg,
    target_line_msg,
    target_power_msg,
    wheel_speed_to_msg,
)
from itt_planner.advice import Advice, Diagnostic, Level
from itt_planner.dds.context import Context
from itt_planner.dds.endpoints import RawReader, RawWriter
from itt_planner.dds.wire import (
    WireQos,
    dds_topic_name,
    dds_type_name,
    idl_struct,
    ros_topic_name,
    ros_type_name,
    to_idl,
)
from itt_planner.samples import GpsFix, PowerReading, WheelSpeed
from itt_planner.state import RiderState


def _advice() -> Advice:
    s = np.linspace(1200.0, 2200.0, 41)
    state = RiderState(stamp_s=RIDE_T0_S + 95.25, s_m=1200.0, n_m=-0.4, speed_mps=13.1,
                       heading_rad=0.7, power_w=402.0, w_prime_j=14_250.5, elapsed_s=95.25,
                       gps_fresh=False)
    return Advice(
        stamp_s=state.stamp_s, state=state, target_power_w=411.5, horizon_s_m=s,
        horizon_power_w=380 + 30 * np.sin(s / 90), horizon_speed_mps=12 + np.cos(s / 70),
        horizon_n_m=np.tanh((s - 1700) / 50), line_x_m=s * 0.8, line_y_m=s * 0.6,
        line_z_m=100 + s * 0.01, line_lat_deg=45.43 + s * 1e-6, line_lon_deg=10.99 + s * 2e-6,
        predicted_finish_s=183.7, w_prime_now_j=14_250.5, w_prime_finish_j=210.0,
        solver_status="Solve_Succeeded", iterations=17, solve_time_s=0.084, fallback=True)


def published_messages() -> dict[str, object]:
    """One realistic message of every type on the interface, keyed by ROS type."""
    advice = _advice()
    clock = typestore.types["rosgraph_msgs/msg/Clock"]
    time_ = typestore.types["builtin_interfaces/msg/Time"]
    diags = [Diagnostic(advice.stamp_s, "itt_planner/solver", Level.WARN, "1 failed solve",
                        {"status": "overrun", "iterations": "40"}),
             Diagnostic(advice.stamp_s, "itt_planner/input/gps", Level.STALE, "no fix", {})]
    msgs = [
        gps_fix_to_msg(GpsFix(RIDE_T0_S + 1.5, 45.4301, 10.9902, 101.25, 3.0)),
        gps_fix_to_msg(GpsFix(RIDE_T0_S + 2.5, 45.4302, 10.9903, 101.5)),  # unknown std
        wheel_speed_to_msg(WheelSpeed(RIDE_T0_S + 0.25, 12.75)),
        power_reading_to_msg(PowerReading(RIDE_T0_S + 0.5, 388.0, 92.0)),
        power_reading_to_msg(PowerReading(RIDE_T0_S + 0.75, 388.0)),  # NaN cadence
        target_power_msg(advice), target_line_msg(advice), advice_to_msg(advice),
        diagnostics_to_msg(diags, advice.stamp_s),
        clock(clock=time_(sec=1795334500, nanosec=250_000_000)),
    ]
    by_type: dict[str, object] = {}
    for msg in msgs:
        by_type.setdefault(type(msg).__msgtype__, msg)
    return by_type


def test_every_interface_type_is_covered() -> None:
    assert {t.msgtype for t in TOPICS} | {"rosgraph_msgs/msg/Clock"} == set(published_messages())


@pytest.mark.parametrize("topic", TOPICS, ids=lambda t: t.key)
def test_topic_and_type_names_follow_ros2_mangling(topic: topics.Topic) -> None:
    name = topic.name()
    assert dds_topic_name(name) == "rt" + name
    assert ros_topic_name(dds_topic_name(name)) == name
    pkg, kind, short = topic.msgtype.split("/")
    assert dds_type_name(topic.msgtype) == f"{pkg}::{kind}::dds_::{short}_"
    assert ros_type_name(dds_type_name(topic.msgtype)) == topic.msgtype
    assert idl_struct(topic.msgtype).__idl_typename__ == dds_type_name(topic.msgtype)


def test_names_of_the_interface() -> None:
    assert dds_topic_name("/itt/gps/fix") == "rt/itt/gps/fix"
    assert dds_topic_name("/diagnostics") == "rt/diagnostics"
    assert dds_type_name("sensor_msgs/msg/NavSatFix") == "sensor_msgs::msg::dds_::NavSatFix_"
    assert dds_type_name("itt_msgs/msg/Advice") == "itt_msgs::msg::dds_::Advice_"
    # Nested types are structs of their own with ROS names (the XTypes type information).
    header = idl_struct("std_msgs/msg/Header")
    assert header.__idl_typename__ == "std_msgs::msg::dds_::Header_"
    assert idl_struct("builtin_interfaces/msg/Time").__idl_typename__ == \
        "builtin_interfaces::msg::dds_::Time_"
    with pytest.raises(ValueError, match="fully qualified"):
        dds_topic_name("itt/gps/fix")
    assert ros_topic_name("DCPSParticipant") is None
    assert ros_type_name("NavSatFix") is None


@pytest.mark.parametrize("msgtype", sorted(published_messages()))
def test_cyclone_encodes_our_types_byte_identical_to_rosbags(msgtype: str) -> None:
    msg = published_messages()[msgtype]
    ours = serialize(msg)
    assert ours[:4] == b"\x00\x01\x00\x00"  # CDR little-endian, XCDR1, no options
    assert to_idl(msg).serialize(use_version_2=False) == ours


def test_qos_of_the_interface() -> None:
    sensor = WireQos(topics.SENSOR_QOS).cyclone()
    assert sensor[Policy.Reliability] == Policy.Reliability.BestEffort
    assert sensor[Policy.History] == Policy.History.KeepLast(5)
    reliable = WireQos(topics.RELIABLE_QOS).cyclone()
    assert isinstance(reliable[Policy.Reliability], Policy.Reliability.Reliable)
    assert reliable[Policy.History] == Policy.History.KeepLast(10)
    for qos in (sensor, reliable):
        assert qos[Policy.DataRepresentation] == Policy.DataRepresentation(
            use_cdrv0_representation=True, use_xcdrv2_representation=False)
        assert qos[Policy.Durability] == Policy.Durability.Volatile


@pytest.fixture(scope="module")
def context() -> Context:
    ctx = Context()
    ctx.init([], random_domain())
    return ctx


def _wait(predicate, timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.02)


def test_raw_bytes_on_the_wire_round_trip_through_typed_cyclone_endpoints(
        context: Context) -> None:
    for msgtype, msg in published_messages().items():
        name = f"/itt/wire/{msgtype.split('/')[-1].lower()}"
        raw_w = RawWriter(context.participant, name, msgtype, topics.RELIABLE_QOS)
        raw_r = RawReader(context.participant, name, msgtype, topics.RELIABLE_QOS)
        qos = WireQos(topics.RELIABLE_QOS).cyclone()
        typed_r = DataReader(context.participant, raw_w.topic, qos)
        typed_w = DataWriter(context.participant, raw_w.topic, qos)
        assert raw_w.topic.name == "rt" + name
        assert raw_w.topic.typename == dds_type_name(msgtype)
        _wait(lambda: raw_w.matched_count() == 2 and raw_r.matched_count() == 2)
        data = serialize(msg)
        raw_w.write(data)  # ours -> Cyclone's typed reader decodes what rosbags encoded
        _wait(lambda: bool(typed_r.read()))
        assert typed_r.take()[0] == to_idl(msg)
        typed_w.write(to_idl(msg))  # Cyclone's typed writer -> our raw reader
        received = []
        _wait(lambda: bool(received.extend(raw_r.take()) or len(received) >= 2))
        assert len(received) == 2, msgtype
        assert received[0].data == data  # exactly the bytes we sent
        # Cyclone pads its own payloads to 4 bytes; the message bytes are rosbags'.
        assert received[1].data[:len(data)] == data
        assert set(received[1].data[len(data):]) <= {0}
        decoded = typestore.deserialize_cdr(received[1].data, msgtype)
        assert serialize(decoded) == data


def test_discovery_sees_ros2_names_and_sensor_qos(context: Context) -> None:
    writer = RawWriter(context.participant, "/itt/gps/fix", "sensor_msgs/msg/NavSatFix",
                       topics.SENSOR_QOS)
    seen = {}
    discovery = BuiltinDataReader(context.participant, BuiltinTopicDcpsPublication)

    def found() -> bool:
        for pub in discovery.take(N=50):
            if hasattr(pub, "topic_name"):
                seen[pub.topic_name] = pub
        return "rt/itt/gps/fix" in seen

    _wait(found)
    pub = seen["rt/itt/gps/fix"]
    assert pub.type_name == "sensor_msgs::msg::dds_::NavSatFix_"
    assert pub.qos[Policy.Reliability] == Policy.Reliability.BestEffort
    assert pub.qos[Policy.History] == Policy.History.KeepLast(5)
    assert writer.matched_count() == 0


def test_cyclone_refuses_bytes_that_are_not_the_type(context: Context) -> None:
    writer = RawWriter(context.participant, "/itt/wire/bad", "sensor_msgs/msg/NavSatFix",
                       topics.RELIABLE_QOS)
    good = serialize(published_messages()["sensor_msgs/msg/NavSatFix"])
    with pytest.raises(DDSException):
        writer.write(good[:40])  # truncated: Cyclone checks the CDR against the struct
    writer.write(good)


def test_nan_values_survive_the_wire_unchanged() -> None:
    msg = power_reading_to_msg(PowerReading(RIDE_T0_S, 300.0))  # no cadence: NaN
    data = serialize(msg)
    assert to_idl(msg).serialize(use_version_2=False) == data
    assert math.isnan(typestore.deserialize_cdr(data, "itt_msgs/msg/PowerStamped").cadence_rpm)
