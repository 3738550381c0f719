"""The default Rerun layout of a ride: every view a coach needs, arranged without clicking.

The entity tree it refers to is `itt_planner.view.rerun_paths`. Left column: the
map (course, GPS track, planned line), the 3D road around the rider and the text log of
advice changes and diagnostics. Right column: power, speed, W', lean / friction use /
solve time, and the elevation profile. The time panel opens on the distance timeline,
where the actual series lie on top of the full-course plan (the paper's figures). The plot
panels and their order are `rerun_paths.PLOT_ROWS`.
"""

from __future__ import annotations

import math

import rerun.blueprint as rrb

from itt_planner.view import rerun_paths as paths
from itt_planner.view.rerun_paths import DISTANCE_TIMELINE, view_origin

DEFAULT_MAP_ZOOM = 13.0
#: Web-Mercator metres per pixel at zoom 0 on the equator.
_MERCATOR_M_PER_PX = 156_543.03
#: Height of the map panel in the default layout on a ~1000 px high window.
_MAP_PANEL_PX = 280.0


def fit_map_zoom(lat_deg: float, extent_m: float, panel_px: float = _MAP_PANEL_PX) -> float:
    """The map zoom level at which `extent_m` of ground fills `panel_px` pixels."""
    m_per_px = max(extent_m, 50.0) / panel_px
    zoom = math.log2(_MERCATOR_M_PER_PX * math.cos(math.radians(lat_deg)) / m_per_px)
    return min(18.0, max(3.0, zoom))


def _map_view(zoom: float) -> rrb.View:
    """The map stays latest-at: the GPS trail is logged as growing segments, so it needs no
    history window (which would also pile up every past horizon line)."""
    return rrb.MapView(origin=view_origin(paths.MAP), name="Map", zoom=zoom)


def _road_view() -> rrb.View:
    # The default eye frames the whole course; the viewer's "track entity" on world/rider
    # follows the rider for a close look at the line.
    return rrb.Spatial3DView(origin=view_origin(paths.WORLD), name="Road (ENU, 3D)")


def _plot(root: str, name: str) -> rrb.TimeSeriesView:
    # The whole ride on the x axis, also while streaming (the viewer would follow the end).
    everything = rrb.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                               end=rrb.TimeRangeBoundary.infinite())
    return rrb.TimeSeriesView(origin=view_origin(root), name=name,
                              axis_x=rrb.TimeAxis(view_range=everything))


def _plot_row(panels: tuple[paths.Panel, ...]) -> rrb.View | rrb.Horizontal:
    """One row of the plot column: a panel, or several side by side."""
    plots = [_plot(panel.root, panel.title) for panel in panels]
    return plots[0] if len(plots) == 1 else rrb.Horizontal(*plots)


def default_blueprint(*, timeline: str = DISTANCE_TIMELINE,
                      map_zoom: float = DEFAULT_MAP_ZOOM) -> rrb.Blueprint:
    """The layout sent with every ride recording.

    Args:
        timeline: the timeline the time panel opens on (`distance_m` or `ride_time`).
        map_zoom: web-map zoom level (`fit_map_zoom` fits a course).
    """
    left = rrb.Vertical(
        _map_view(map_zoom),
        _road_view(),
        rrb.TextLogView(origin=view_origin(paths.LOG), name="Advice and diagnostics"),
        row_shares=[3.0, 3.0, 2.0],
    )
    right = rrb.Vertical(
        *(_plot_row(panels) for panels, _share in paths.PLOT_ROWS),
        row_shares=[share for _panels, share in paths.PLOT_ROWS],
    )
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[2.0, 3.0]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline=timeline),
        auto_views=False,
    )
