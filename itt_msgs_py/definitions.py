"""The message types: a rosbags typestore with the custom `itt_msgs` types registered.

The custom types are read from the `.msg` files of the ROS interface package
(`ros_ws/src/itt_msgs/msg/`, shipped here as package data through the `msg` symlink), so
ROS and the core share one definition. Standard types come from rosbags' ROS 2 Jazzy
store. `msgdef` gives the concatenated definition text that `ros2 bag record` stores as
an MCAP `ros2msg` schema.
"""

from __future__ import annotations

import re
from functools import cache
from importlib.resources import files

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

PACKAGE = "itt_msgs"
#: The separator between definitions in a concatenated ROS 2 message definition.
SEPARATOR = "=" * 80


def msg_texts() -> dict[str, str]:
    """The text of every `.msg` file of the interface package, keyed by type name."""
    folder = files("itt_msgs_py") / "msg"
    texts = {
        f"{PACKAGE}/msg/{entry.name.removesuffix('.msg')}": entry.read_text(encoding="utf-8")
        for entry in folder.iterdir()
        if entry.name.endswith(".msg")
    }
    if not texts:  # a broken install would otherwise fail much later, on the first message
        raise RuntimeError(f"no .msg files found in {folder}: itt_msgs_py is not installed right")
    return dict(sorted(texts.items()))


@cache
def build_typestore() -> Typestore:
    """ROS 2 Jazzy types plus the custom `itt_msgs` types (built once)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name, text in msg_texts().items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


typestore = build_typestore()


@cache
def msgdef(msgtype: str) -> str:
    """The full `ros2msg` definition of `msgtype`, as `ros2 bag record` writes it.

    The type's own text, then for each type it depends on a line of 80 `=`, a line
    `MSG: pkg/Name` and that type's text. Custom types keep their `.msg` text verbatim
    (with comments); standard types use the text rosbags regenerates from its store.

    Raises:
        KeyError: unknown message type.
    """
    if msgtype not in typestore.fielddefs:
        raise KeyError(f"unknown message type {msgtype!r}")
    generated, _ = typestore.generate_msgdef(msgtype, ros_version=2)
    blocks = generated.split(f"{SEPARATOR}\n")
    custom = msg_texts()
    parts = [custom.get(msgtype, blocks[0]).rstrip("\n") + "\n"]
    for block in blocks[1:]:
        header, _, body = block.partition("\n")
        dep = re.fullmatch(r"MSG: (\w+)/(\w+)", header)
        if dep is None:  # rosbags' format changed: fail loudly instead of writing bad schemas
            raise RuntimeError(f"unexpected dependency header {header!r} for {msgtype}")
        full = f"{dep[1]}/msg/{dep[2]}"
        parts.append(f"{header}\n" + custom.get(full, body).rstrip("\n") + "\n")
    return f"{SEPARATOR}\n".join(parts)
