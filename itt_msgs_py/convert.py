"""Conversions between the core's outputs and ROS 2 message objects (rosbags classes).

The input samples' converters are in `registry`, one entry per input topic.

Stamps: the core uses float seconds on the ride clock, ROS `builtin_interfaces/Time`
(sec, nanosec); the split keeps nanosecond resolution for POSIX times, which a single
float64 of nanoseconds would lose (its step is 256 ns at 1.7e18).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from itt_msgs_py import topics
from itt_msgs_py.definitions import typestore
from itt_planner.live.advice import Advice, Cue, Diagnostic, Level
from itt_planner.model.state import RiderState

_T = typestore.types
Time = _T["builtin_interfaces/msg/Time"]
Header = _T["std_msgs/msg/Header"]
Path = _T["nav_msgs/msg/Path"]
PoseStamped = _T["geometry_msgs/msg/PoseStamped"]
Pose = _T["geometry_msgs/msg/Pose"]
Point = _T["geometry_msgs/msg/Point"]
Quaternion = _T["geometry_msgs/msg/Quaternion"]
DiagnosticArray = _T["diagnostic_msgs/msg/DiagnosticArray"]
DiagnosticStatus = _T["diagnostic_msgs/msg/DiagnosticStatus"]
KeyValue = _T["diagnostic_msgs/msg/KeyValue"]
TargetPower = _T["itt_msgs/msg/TargetPower"]
RiderStateMsg = _T["itt_msgs/msg/RiderState"]
AdviceMsg = _T["itt_msgs/msg/Advice"]

#: Frames (REP-103/105): the course's ENU frame, the GNSS antenna, the bicycle.
MAP_FRAME = "map"
GPS_FRAME = "gps"
BASE_FRAME = "base_link"
HARDWARE_ID = "itt_planner"


def stamp_ns(stamp_s: float) -> int:
    """Nanoseconds of a float stamp, split as `Time` does (exact for whole seconds)."""
    t = to_time(stamp_s)
    return int(t.sec * 1_000_000_000 + t.nanosec)


def to_time(stamp_s: float) -> Any:
    """`builtin_interfaces/Time` of a float stamp in seconds."""
    sec = math.floor(stamp_s)
    nanosec = round((stamp_s - sec) * 1e9)
    if nanosec >= 1_000_000_000:  # rounding carried into the next second
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return Time(sec=int(sec), nanosec=int(nanosec))


def from_time(time: Any) -> float:
    """Float seconds of a `builtin_interfaces/Time`."""
    return float(time.sec + time.nanosec * 1e-9)


def header(stamp_s: float, frame_id: str) -> Any:
    """`std_msgs/Header` with the stamp and frame."""
    return Header(stamp=to_time(stamp_s), frame_id=frame_id)


# --- outputs ---------------------------------------------------------------------------

def state_to_msg(state: RiderState) -> Any:
    """`itt_msgs/RiderState`."""
    return RiderStateMsg(
        stamp=to_time(state.stamp_s), s_m=state.s_m, n_m=state.n_m, speed_mps=state.speed_mps,
        heading_rad=state.heading_rad, power_w=state.power_w, w_prime_j=state.w_prime_j,
        elapsed_s=state.elapsed_s, gps_fresh=state.gps_fresh,
    )


def msg_to_state(msg: Any) -> RiderState:
    """`RiderState` of an `itt_msgs/RiderState`."""
    return RiderState(
        stamp_s=from_time(msg.stamp), s_m=msg.s_m, n_m=msg.n_m, speed_mps=msg.speed_mps,
        heading_rad=msg.heading_rad, power_w=msg.power_w, w_prime_j=msg.w_prime_j,
        elapsed_s=msg.elapsed_s, gps_fresh=bool(msg.gps_fresh),
    )


def _f64(values: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float64)


def advice_to_msg(advice: Advice) -> Any:
    """`itt_msgs/Advice` (frame `map`), holding everything of the core `Advice`."""
    return AdviceMsg(
        header=header(advice.stamp_s, MAP_FRAME), state=state_to_msg(advice.state),
        target_power_w=advice.target_power_w, cue=int(advice.cue),
        corner_speed_mps=advice.corner_speed_mps, corner_distance_m=advice.corner_distance_m,
        cp_in_use_w=advice.cp_in_use_w, plan_version=int(advice.plan_version),
        s_m=_f64(advice.horizon_s_m), power_w=_f64(advice.horizon_power_w),
        speed_mps=_f64(advice.horizon_speed_mps), n_m=_f64(advice.horizon_n_m),
        line_x_m=_f64(advice.line_x_m), line_y_m=_f64(advice.line_y_m),
        line_z_m=_f64(advice.line_z_m), line_lat_deg=_f64(advice.line_lat_deg),
        line_lon_deg=_f64(advice.line_lon_deg),
        predicted_finish_s=advice.predicted_finish_s, w_prime_now_j=advice.w_prime_now_j,
        w_prime_finish_j=advice.w_prime_finish_j, solver_status=advice.solver_status,
        iterations=int(advice.iterations), solve_time_s=advice.solve_time_s,
        fallback=bool(advice.fallback),
    )


def msg_to_advice(msg: Any) -> Advice:
    """Core `Advice` of an `itt_msgs/Advice`."""
    return Advice(
        stamp_s=from_time(msg.header.stamp), state=msg_to_state(msg.state),
        target_power_w=msg.target_power_w, horizon_s_m=np.array(msg.s_m),
        horizon_power_w=np.array(msg.power_w), horizon_speed_mps=np.array(msg.speed_mps),
        horizon_n_m=np.array(msg.n_m), line_x_m=np.array(msg.line_x_m),
        line_y_m=np.array(msg.line_y_m), line_z_m=np.array(msg.line_z_m),
        line_lat_deg=np.array(msg.line_lat_deg), line_lon_deg=np.array(msg.line_lon_deg),
        predicted_finish_s=msg.predicted_finish_s, w_prime_now_j=msg.w_prime_now_j,
        w_prime_finish_j=msg.w_prime_finish_j, solver_status=msg.solver_status,
        iterations=msg.iterations, solve_time_s=msg.solve_time_s, fallback=bool(msg.fallback),
        cue=Cue(msg.cue), corner_speed_mps=msg.corner_speed_mps,
        corner_distance_m=msg.corner_distance_m, cp_in_use_w=msg.cp_in_use_w,
        plan_version=int(msg.plan_version),
    )


def target_power_msg(advice: Advice) -> Any:
    """`itt_msgs/TargetPower` of an advice: the power now, the cue and the next corner,
    and the planned speed here."""
    speed = float(advice.horizon_speed_mps[0]) if len(advice.horizon_speed_mps) else math.nan
    return TargetPower(header=header(advice.stamp_s, BASE_FRAME), power_w=advice.target_power_w,
                       cue=int(advice.cue), corner_speed_mps=advice.corner_speed_mps,
                       corner_distance_m=advice.corner_distance_m,
                       speed_mps=speed, fallback=bool(advice.fallback))


def line_yaw_rad(x_m: np.ndarray, y_m: np.ndarray, fallback_rad: float) -> np.ndarray:
    """Heading of a polyline at each point (ENU, rad), `fallback_rad` for a single point."""
    if len(x_m) < 2:
        return np.full(len(x_m), fallback_rad)
    yaw: np.ndarray = np.arctan2(np.gradient(y_m), np.gradient(x_m))
    return yaw


def target_line_msg(advice: Advice) -> Any:
    """`nav_msgs/Path` of the planned line in the `map` frame.

    Each pose points along the line (yaw only, so RViz arrows lie flat on the road).
    """
    yaw = line_yaw_rad(np.asarray(advice.line_x_m), np.asarray(advice.line_y_m),
                       advice.state.heading_rad)
    hdr = header(advice.stamp_s, MAP_FRAME)
    poses = [
        PoseStamped(header=hdr, pose=Pose(
            position=Point(x=float(x), y=float(y), z=float(z)),
            orientation=Quaternion(x=0.0, y=0.0, z=math.sin(a / 2), w=math.cos(a / 2))))
        for x, y, z, a in zip(advice.line_x_m, advice.line_y_m, advice.line_z_m, yaw,
                              strict=True)
    ]
    return Path(header=hdr, poses=poses)


def diagnostics_to_msg(diagnostics: list[Diagnostic], stamp_s: float) -> Any:
    """`diagnostic_msgs/DiagnosticArray` of the engine's health items."""
    return DiagnosticArray(
        header=header(stamp_s, ""),
        status=[
            DiagnosticStatus(level=int(d.level), name=d.name, message=d.message,
                             hardware_id=HARDWARE_ID,
                             values=[KeyValue(key=k, value=v) for k, v in d.values.items()])
            for d in diagnostics
        ],
    )


def msg_to_diagnostics(msg: Any) -> list[Diagnostic]:
    """Core `Diagnostic`s of a `DiagnosticArray` (each gets the array's stamp)."""
    stamp = from_time(msg.header.stamp)
    return [
        Diagnostic(stamp_s=stamp, name=st.name, level=Level(st.level), message=st.message,
                   values={kv.key: kv.value for kv in st.values})
        for st in msg.status
    ]


#: Core value of an output message, per message type; types without a core twin stay
#: messages. (Inputs: `registry.to_core`.)
_TO_CORE = {
    topics.ADVICE.msgtype: msg_to_advice,
    topics.DIAGNOSTICS.msgtype: msg_to_diagnostics,
}


def output_to_core(msg: Any) -> object:
    """The core object of an output message (`Advice`, list of `Diagnostic`), or the
    message itself for types the core has no twin of (`TargetPower`, `Path`)."""
    convert = _TO_CORE.get(type(msg).__msgtype__)
    return msg if convert is None else convert(msg)
