"""CDR encoding of ROS 2 messages without a ROS install (rosbags' serializer).

The payload is what ROS 2 puts on the wire and in bags: little-endian CDR with the
4-byte encapsulation header, so the DDS layer and the MCAP logs share these bytes.
"""

from __future__ import annotations

from itt_msgs_py.definitions import typestore


def serialize(msg: object) -> bytes:
    """CDR bytes of a rosbags message object (its type is `msg.__msgtype__`).

    Raises:
        KeyError: `msg` is not a message of the typestore.
    """
    msgtype = getattr(type(msg), "__msgtype__", None)
    if msgtype is None or msgtype not in typestore.types:
        raise KeyError(f"not a ROS message of the itt typestore: {type(msg).__name__}")
    return bytes(typestore.serialize_cdr(msg, msgtype, little_endian=True))


def deserialize(data: bytes | memoryview, msgtype: str) -> object:
    """Message object of type `msgtype` from CDR bytes.

    Raises:
        KeyError: unknown `msgtype`.
        rosbags.serde.SerdeError: the bytes are not a valid CDR message of that type.
    """
    if msgtype not in typestore.types:
        raise KeyError(f"unknown message type {msgtype!r}")
    return typestore.deserialize_cdr(data, msgtype)
