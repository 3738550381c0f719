"""The default Rerun layout of a ride: every view a coach needs, arranged without clicking.

The entity tree it refers to is documented in `itt_planner.rerun_log`. Left column: the
map (course, GPS track, planned line), the 3D road around the rider and the text log of
advice changes and diagnostics. Right column: power, speed, W', lean / friction use /
solve time, and the elevation profile. The time panel opens on the distance timeline,
where the actual series lie on top of the full-course plan (the paper's figures).
"""

from __future__ import annotations

import rerun.blueprint as rrb

#: Timelines of a ride recording (see `itt_planner.rerun_log`).
RIDE_TIMELINE = "ride_time"
DISTANCE_TIMELINE = "distance_m"

_MAP_ZOOM = 14.0


def _map_view() -> rrb.View:
    """The map stays latest-at: the GPS trail is logged as growing segments, so it needs no
    history window (which would also pile up every past horizon line)."""
    return rrb.MapView(origin="/map", name="Map", zoom=_MAP_ZOOM)


def _road_view() -> rrb.View:
    # The default eye frames the whole course; the viewer's "track entity" on world/rider
    # follows the rider for a close look at the line.
    return rrb.Spatial3DView(origin="/world", name="Road (ENU, 3D)")


def _plot(origin: str, name: str) -> rrb.TimeSeriesView:
    return rrb.TimeSeriesView(origin=origin, name=name)


def default_blueprint(*, timeline: str = DISTANCE_TIMELINE) -> rrb.Blueprint:
    """The layout sent with every ride recording.

    Args:
        timeline: the timeline the time panel opens on (`distance_m` or `ride_time`).
    """
    left = rrb.Vertical(
        _map_view(),
        _road_view(),
        rrb.TextLogView(origin="/log", name="Advice and diagnostics"),
        row_shares=[3.0, 3.0, 2.0],
    )
    right = rrb.Vertical(
        _plot("/plots/power", "Power (W)"),
        _plot("/plots/speed_kmh", "Speed (km/h)"),
        _plot("/plots/w_prime_kj", "W' balance (kJ)"),
        rrb.Horizontal(
            _plot("/plots/lean_deg", "Lean (deg)"),
            _plot("/plots/friction_use", "Friction-ellipse use"),
            _plot("/plots/solve_time_ms", "Replan solve time (ms)"),
        ),
        _plot("/elevation", "Elevation (m)"),
        row_shares=[3.0, 3.0, 2.0, 2.0, 2.0],
    )
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[2.0, 3.0]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline=timeline),
        auto_views=False,
    )
