"""ROS 2 wire conventions on Cyclone DDS (what `rmw_cyclonedds_cpp` puts on the wire).

* topic names: `rt` + the fully qualified ROS name (`/itt/gps/fix` -> `rt/itt/gps/fix`);
* type names: `pkg::msg::dds_::Name_` (`sensor_msgs::msg::dds_::NavSatFix_`);
* payloads: XCDR1 little-endian with the 4-byte encapsulation header, i.e. exactly what
  `rosbags` serialises (`itt_msgs_py.serialize`).

Each ROS message type is described to Cyclone by an `IdlStruct` built from the rosbags
type definition (nested types are nested structs with their own mangled names), so the
topic's type name and its XTypes type information are those of the ROS type. Payloads
are written and taken as opaque CDR bytes: no Python object per sample, and the bytes
on the wire are rosbags' bytes. Cyclone still checks every payload against the struct
(a truncated or garbled one is refused on write and dropped on receipt).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

from cyclonedds.idl import IdlStruct, make_idl_struct
from cyclonedds.idl import types as idl
from cyclonedds.qos import Policy, Qos
from rosbags.typesys.store import Nodetype

from itt_msgs_py import typestore
from itt_msgs_py.topics import Durability, History, QoS, Reliability

TOPIC_PREFIX = "rt"

#: ROS 2 primitive types -> IDL (rosidl: `byte` is an octet, `char` an uint8).
_PRIMITIVES: dict[str, Any] = {
    "bool": bool, "byte": idl.byte, "char": idl.uint8,
    "int8": idl.int8, "uint8": idl.uint8, "int16": idl.int16, "uint16": idl.uint16,
    "int32": idl.int32, "uint32": idl.uint32, "int64": idl.int64, "uint64": idl.uint64,
    "float32": idl.float32, "float64": idl.float64,
}


def dds_topic_name(ros_name: str) -> str:
    """DDS topic of a fully qualified ROS topic name.

    Raises:
        ValueError: the name is not fully qualified (does not start with `/`).
    """
    if not ros_name.startswith("/"):
        raise ValueError(f"ROS topic {ros_name!r} is not fully qualified")
    return TOPIC_PREFIX + ros_name


def ros_topic_name(dds_name: str) -> str | None:
    """ROS topic of a DDS topic name, None for topics that are not ROS topics."""
    if dds_name.startswith(TOPIC_PREFIX + "/"):
        return dds_name[len(TOPIC_PREFIX):]
    return None


def dds_type_name(msgtype: str) -> str:
    """DDS type name of a ROS type `pkg/msg/Name`.

    Raises:
        ValueError: not of the form `pkg/msg/Name`.
    """
    parts = msgtype.split("/")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"ROS type {msgtype!r} is not of the form pkg/msg/Name")
    pkg, kind, name = parts
    return f"{pkg}::{kind}::dds_::{name}_"


def ros_type_name(dds_name: str) -> str | None:
    """ROS type `pkg/msg/Name` of a DDS type name, None if it is not a ROS type."""
    parts = dds_name.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        return None
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"


def _field_type(desc: tuple[Any, Any]) -> Any:
    kind, rest = desc
    if kind == Nodetype.BASE:
        name, bound = rest
        if name == "string":
            return idl.bounded_str[bound] if bound else str
        if name not in _PRIMITIVES:
            raise TypeError(f"ROS type {name!r} has no IDL mapping here")
        return _PRIMITIVES[name]
    if kind == Nodetype.NAME:
        return idl_struct(rest)
    sub, size = rest
    if kind == Nodetype.ARRAY:
        return idl.array[_field_type(sub), size]
    return idl.sequence[_field_type(sub), size] if size else idl.sequence[_field_type(sub)]


@cache
def idl_struct(msgtype: str) -> type[IdlStruct]:
    """The Cyclone IDL struct of a ROS message type of the itt typestore (built once).

    Raises:
        KeyError: `msgtype` is not in the typestore.
        TypeError: a field has a type without an IDL mapping (`wstring`).
    """
    _, fields = typestore.fielddefs[msgtype]
    pkg, _, name = msgtype.split("/")
    return make_idl_struct(f"{pkg}_msg_{name}", dds_type_name(msgtype),
                           {field: _field_type(desc) for field, desc in fields})


def to_idl(msg: Any) -> IdlStruct:
    """The IDL struct instance of a rosbags message (to let Cyclone serialise it too)."""
    msgtype = type(msg).__msgtype__
    _, fields = typestore.fielddefs[msgtype]
    return idl_struct(msgtype)(**{f: _value(getattr(msg, f), d) for f, d in fields})


def _value(value: Any, desc: tuple[Any, Any]) -> Any:
    kind, rest = desc
    if kind == Nodetype.BASE:
        return value.item() if hasattr(value, "item") else value
    if kind == Nodetype.NAME:
        return to_idl(value)
    return [_value(v, rest[0]) for v in value]


@dataclass(frozen=True)
class WireQos:
    """The Cyclone QoS of a ROS QoS profile (as plain `itt_msgs_py.topics.QoS`)."""

    qos: QoS

    def cyclone(self) -> Qos:
        """Cyclone `Qos` with XCDR1 data representation, as ROS 2 peers expect."""
        reliability = (Policy.Reliability.Reliable(max_blocking_time=100_000_000)
                       if self.qos.reliability is Reliability.RELIABLE
                       else Policy.Reliability.BestEffort)
        history = (Policy.History.KeepLast(self.qos.depth)
                   if self.qos.history is History.KEEP_LAST else Policy.History.KeepAll)
        durability = (Policy.Durability.TransientLocal
                      if self.qos.durability is Durability.TRANSIENT_LOCAL
                      else Policy.Durability.Volatile)
        return Qos(reliability, history, durability,
                   Policy.DataRepresentation(use_cdrv0_representation=True))
