"""The entity paths and timelines of a ride recording, named once for the recorder and the layout.

`rerun_log` logs to these paths, `rerun_blueprint` points its views at the panel roots
(`MAP`, `WORLD`, `LOG`) and lays out the time-series panels of `PLOT_ROWS`. A new plot
panel is one root here, its series under it, one row of `PLOT_ROWS`, and the recorder's
view that logs to it; a new scalar sensor's view is its entry in `SAMPLE_SERIES`.

Timelines:
    ride_time   the message stamps: a timestamp timeline for POSIX stamps (recorded
                rides), a duration timeline for stamps counted from 0 (simulations).
    distance_m  arc length along the course (sequence, whole metres), from the latest
                rider state; the full-course plan curves live only on this timeline.

Entities (display units, at the edge: km/h, degrees, kJ, ms, named in the path):
    map/course                  GeoLineStrings, static: course centre line (EPSG:4326)
    map/plan_line               GeoLineStrings, static: the full-course planned line
    map/gps                     GeoPoints: latest raw GPS fix
    map/track/seg_NNNN          GeoLineStrings: the GPS track, in segments of 60 fixes
    map/rider                   GeoPoints: estimated position (s, n) of the rider
    map/target_line             GeoLineStrings: planned line over the horizon (per advice)
    world                       ViewCoordinates RIGHT_HAND_Z_UP (ENU, metres), static
    world/road                  Mesh3D, static: the road ribbon from w_L(s), w_R(s)
    world/road/edges            LineStrips3D, static: left and right road edges
    world/road/centre           LineStrips3D, static: centre line
    world/plan_line             LineStrips3D, static: the full-course planned line
    world/target_line           LineStrips3D: planned line over the horizon (per advice)
    world/rider                 Points3D: estimated position of the rider
    world/path/seg_NNNN         LineStrips3D: the rider's estimated path (a point per 5 m)
    plots/power/{actual,target,critical,plan}          W ("critical": the CP in use, from
                                                       each advice: refits show as steps;
                                                       "plan": its pedalling, braking as 0)
    plots/speed_kmh/{actual,plan}                      km/h
    plots/w_prime_kj/{actual,finish,plan}              kJ ("finish": projected at the line)
    plots/lean_deg/plan                                deg
    plots/friction_use/plan                            C16 left-hand side (<= 1)
    plots/solve_time_ms/replan                         points: ms per receding-horizon
                                                       solve (none on the plan)
    elevation/profile           Scalars on distance_m: z(s) of the course
    elevation/rider             Scalars (points): z at the rider's position
    log/advice                  TextLog: advice changes (target, cue, status, fallback)
    log/belief                  TextLog: CP refits and plan adoptions, as the advice
                                reports them (`cp_in_use_w`, `plan_version`)
    log/diagnostics             TextLog: diagnostic changes (solver, inputs, fallbacks)
    log/inputs                  TextLog: inputs the recorder could not plot (NaN, inf, a
                                sample type without a view)
"""

from __future__ import annotations

from dataclasses import dataclass

from itt_planner.live.samples import PowerReading, WheelSpeed
from itt_planner.units import MPS_TO_KMH

RIDE_TIMELINE = "ride_time"
DISTANCE_TIMELINE = "distance_m"

# ---- panel roots (the blueprint's view origins) ------------------------------------------
MAP = "map"
WORLD = "world"
LOG = "log"
POWER = "plots/power"
SPEED = "plots/speed_kmh"
W_PRIME = "plots/w_prime_kj"
LEAN = "plots/lean_deg"
FRICTION_USE = "plots/friction_use"
SOLVE_TIME = "plots/solve_time_ms"
ELEVATION = "elevation"

# ---- map ---------------------------------------------------------------------------------
MAP_COURSE = f"{MAP}/course"
MAP_PLAN_LINE = f"{MAP}/plan_line"
MAP_GPS = f"{MAP}/gps"
MAP_RIDER = f"{MAP}/rider"
MAP_TARGET_LINE = f"{MAP}/target_line"

# ---- 3D road -----------------------------------------------------------------------------
ROAD = f"{WORLD}/road"
ROAD_EDGES = f"{ROAD}/edges"
ROAD_CENTRE = f"{ROAD}/centre"
WORLD_PLAN_LINE = f"{WORLD}/plan_line"
WORLD_TARGET_LINE = f"{WORLD}/target_line"
WORLD_RIDER = f"{WORLD}/rider"

# ---- plots -------------------------------------------------------------------------------
POWER_ACTUAL = f"{POWER}/actual"
POWER_TARGET = f"{POWER}/target"
POWER_CRITICAL = f"{POWER}/critical"
POWER_PLAN = f"{POWER}/plan"
SPEED_ACTUAL = f"{SPEED}/actual"
SPEED_PLAN = f"{SPEED}/plan"
W_PRIME_ACTUAL = f"{W_PRIME}/actual"
W_PRIME_FINISH = f"{W_PRIME}/finish"
W_PRIME_PLAN = f"{W_PRIME}/plan"
LEAN_PLAN = f"{LEAN}/plan"
FRICTION_USE_PLAN = f"{FRICTION_USE}/plan"
SOLVE_TIME_REPLAN = f"{SOLVE_TIME}/replan"
ELEVATION_PROFILE = f"{ELEVATION}/profile"
ELEVATION_RIDER = f"{ELEVATION}/rider"


@dataclass(frozen=True)
class Panel:
    """A time-series panel of the default layout: the entity root it shows, its title."""

    root: str
    title: str


#: The right column of the default layout, top to bottom: each row's panels (side by
#: side) and its share of the column's height.
PLOT_ROWS: tuple[tuple[tuple[Panel, ...], float], ...] = (
    ((Panel(POWER, "Power (W)"),), 3.0),
    ((Panel(SPEED, "Speed (km/h)"),), 3.0),
    ((Panel(W_PRIME, "W' balance (kJ)"),), 2.0),
    ((Panel(LEAN, "Lean (deg)"), Panel(FRICTION_USE, "Friction-ellipse use"),
      Panel(SOLVE_TIME, "Replan solve time (ms)")), 2.0),
    ((Panel(ELEVATION, "Elevation (m)"),), 2.0),
)

@dataclass(frozen=True)
class SampleSeries:
    """How the recorder draws an input sample of one value: the series it goes to, the
    sample's field, the factor to the series' display unit, and the sample's name in
    log/inputs (a value it cannot plot)."""

    path: str
    field: str
    scale: float
    label: str


#: The input samples of one value and their series (`RideRecorder.log_sample`). A new
#: scalar sensor: its entry here, with its panel root, series and `PLOT_ROWS` row above.
#: GPS fixes have a view of their own (map and track).
SAMPLE_SERIES: dict[type, SampleSeries] = {
    WheelSpeed: SampleSeries(SPEED_ACTUAL, "speed_mps", MPS_TO_KMH, "wheel speed"),
    PowerReading: SampleSeries(POWER_ACTUAL, "power_w", 1.0, "power"),
}

# ---- text logs ---------------------------------------------------------------------------
LOG_ADVICE = f"{LOG}/advice"
LOG_BELIEF = f"{LOG}/belief"
LOG_DIAGNOSTICS = f"{LOG}/diagnostics"
LOG_INPUTS = f"{LOG}/inputs"
LOG_SESSION = f"{LOG}/session"


def map_track_segment(index: int) -> str:
    """The GPS track's segment `index` (each a bounded polyline, see `rerun_log._Trail`)."""
    return f"{MAP}/track/seg_{index:04d}"


def world_path_segment(index: int) -> str:
    """The rider's estimated 3D path, segment `index`."""
    return f"{WORLD}/path/seg_{index:04d}"


def view_origin(root: str) -> str:
    """The blueprint origin of a panel root (an absolute entity path)."""
    return f"/{root}"
