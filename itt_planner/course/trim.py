"""Trim a ride to the race: where it starts and where it finishes.

A ride file holds more than the race: the roll to the start, warm-up loops, and after the
line the rider sits up, turns round and rides back to the team car. Left in, a
post-finish U-turn becomes a 170 deg "corner" the plan brakes for (issue 14). Three ways
to find the race, in order of precedence:

1. overrides: `start` / `finish` given as a distance along the ride (`"1.2km"`,
   `"850m"`, `"850"`) or as the elapsed time from its first record (`"4:10"`,
   `"1:02:03"`, `"250s"`);
2. a route (the race's planned GPS track): the race starts at the last pass near the
   route's start line heading the route's way from which the ride reaches the route's
   finish after 80-130 % of the route's length, and ends there;
3. heuristics (`auto`): a U-turn (heading reversed within +-`uturn_reach_m`, the two
   legs less than `uturn_gap_m` apart) in the last 20 % of the ride (at most 5 km) is
   the turn-round after the line: the course ends where the turn begins. The same turn
   in the first 20 % is the roll-out before the start. An out-and-back course turns
   near half way and is left alone.

Distances are along the cleaned GPS fixes (`track_clean`), from the first moving fix.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pymap3d
import scipy.ndimage

from itt_planner.course.track_clean import Track
from itt_planner.course.track_files import Recording
from itt_planner.errors import CourseError

#: A turn-round is a heading reversal within this reach before and after it (m)...
UTURN_REACH_M = 30.0
#: ... whose two legs come this close (m) ...
UTURN_GAP_M = 25.0
#: ... and that turns at least this much (deg).
UTURN_MIN_DEG = 150.0
#: Only the first / last this fraction of the ride (and at most `EDGE_MAX_M`) is warm-up
#: or cool-down; a turn in the middle is course (out-and-back).
EDGE_FRACTION = 0.2
EDGE_MAX_M = 5000.0
#: A rider who sits up after the line turns round within this distance of it (m).
RUNOUT_M = 500.0
#: A finish this close to the ride's start is on its start line (m).
START_MATCH_M = 30.0
#: The ride passes a route's start / finish within this distance (m).
ROUTE_MATCH_M = 50.0
#: A heuristic cut longer than this (m) is a warning, not only a note: a guess that
#: drops kilometres of the ride (a training ride's first U-turn) must be seen.
CUT_WARN_M = 1000.0


@dataclass(frozen=True)
class Mark:
    """A point of the ride: a distance along it (m) or an elapsed time from its start (s)."""

    distance_m: float | None = None
    elapsed_s: float | None = None

    def __str__(self) -> str:
        if self.distance_m is not None:
            return f"{self.distance_m:.0f} m"
        return f"{self.elapsed_s:.0f} s"


def parse_mark(text: str | float | None) -> Mark | None:
    """`"1.2km"`, `"850m"`, `850` (metres), `"250s"`, `"4:10"`, `"1:02:03"`; None/"auto" -> None.

    Raises:
        CourseError: anything else.
    """
    if text is None:
        return None
    if isinstance(text, (int, float)):
        return Mark(distance_m=float(text))
    raw = text.strip().lower()
    if raw in ("", "auto"):
        return None
    if re.fullmatch(r"\d+(:\d{1,2}){1,2}", raw):
        parts = [int(p) for p in raw.split(":")]
        seconds = 0
        for p in parts:
            seconds = 60 * seconds + p
        return Mark(elapsed_s=float(seconds))
    m = re.fullmatch(r"([0-9]*\.?[0-9]+)\s*(km|m|s)?", raw)
    if m is None:
        raise CourseError(f"start/finish {text!r}: expected a distance ('850m', '1.2km', "
                          "'850') or a time ('4:10', '1:02:03', '250s')")
    value, unit = float(m.group(1)), m.group(2) or "m"
    if unit == "s":
        return Mark(elapsed_s=value)
    return Mark(distance_m=value * (1000.0 if unit == "km" else 1.0))


@dataclass(frozen=True)
class TrimOptions:
    """How to find the race in a ride: overrides, a route, and/or the heuristics."""

    start: Mark | None = None
    finish: Mark | None = None
    route: Recording | None = None
    auto: bool = True


@dataclass(frozen=True)
class TrimReport:
    """What trimming did, in metres along the ride's cleaned fixes (and elapsed seconds)."""

    ride_length_m: float
    start_m: float
    finish_m: float
    start_method: str
    finish_method: str
    start_elapsed_s: float | None = None
    finish_elapsed_s: float | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)

    def as_dict(self) -> dict[str, Any]:
        def r(v: float | None) -> float | None:
            return None if v is None else round(v, 1)
        return {"ride_length_m": r(self.ride_length_m), "start_m": r(self.start_m),
                "finish_m": r(self.finish_m), "start_method": self.start_method,
                "finish_method": self.finish_method, "start_elapsed_s": r(self.start_elapsed_s),
                "finish_elapsed_s": r(self.finish_elapsed_s),
                "cut_before_m": r(self.start_m),
                "cut_after_m": r(self.ride_length_m - self.finish_m), "notes": list(self.notes)}

    def warnings(self) -> list[str]:
        """The heuristic cuts longer than `CUT_WARN_M` (overrides and a route are meant)."""
        out = []
        if self.start_method == "u-turn" and self.start_m > CUT_WARN_M:
            out.append(f"the first {self.start_m / 1000:.2f} km of the ride were cut as the "
                       "roll-out before the start (a U-turn there): if the race started "
                       "earlier, pass --start (--start 0 keeps it all)")
        cut_after = self.ride_length_m - self.finish_m
        if self.finish_method == "u-turn" and cut_after > CUT_WARN_M:
            out.append(f"the last {cut_after / 1000:.2f} km of the ride were cut as the ride "
                       "back after the finish (a U-turn there): if the race went on, pass "
                       "--finish (with the ride's length to keep it all)")
        return out


def trim_track(track: Track, rec: Recording, options: TrimOptions = TrimOptions()
               ) -> tuple[Track, TrimReport]:
    """The fixes of the race, and what was cut.

    Raises:
        CourseError: an override outside the ride or finish before start, a route the ride
            does not follow, or fewer than 3 fixes left (names the file).
    """
    where = str(rec.path)
    dist = track.distance_m
    length = float(dist[-1])
    elapsed = None
    if rec.time_s is not None and np.isfinite(rec.time_s).any():
        t0 = float(np.nanmin(rec.time_s))
        elapsed = np.asarray(rec.time_s, float)[track.index] - t0
    notes: list[str] = []
    i0, i1 = 0, len(track) - 1
    how0 = how1 = "none"
    if options.route is not None and (options.start is None or options.finish is None):
        r0, r1 = _route_match(track, dist, options.route, where)
        if options.start is None:
            i0, how0 = r0, "route"
        if options.finish is None:
            i1, how1 = r1, "route"
    elif options.auto:
        turns = find_uturns(track.x_m, track.y_m, dist)
        edge = min(EDGE_FRACTION * length, EDGE_MAX_M)
        late = [t for t in turns if t[0] >= length - edge]
        early = [t for t in turns if t[0] <= edge]
        if options.finish is None and late:
            s_turn, angle = late[-1]
            i1 = int(np.searchsorted(dist, s_turn - UTURN_REACH_M))
            how1 = "u-turn"
            # A course that finishes where it started (a loop, an out-and-back): the line
            # is where the ride last passed its start before the turn.
            back = np.flatnonzero((dist >= dist[i1] - RUNOUT_M) & (dist <= dist[i1]))
            gap = np.hypot(track.x_m[back] - track.x_m[0], track.y_m[back] - track.y_m[0])
            at_start = dist[i1] > 2 * RUNOUT_M and gap.min() <= START_MATCH_M
            if at_start:
                i1 = int(back[np.argmin(gap)])
            notes.append(f"a {angle:.0f} deg U-turn at {s_turn:.0f} m of {length:.0f} m is the "
                         "turn-round after the line: finish set "
                         + (f"where the ride passed its start {s_turn - dist[i1]:.0f} m before"
                            if at_start else f"{UTURN_REACH_M:.0f} m before it")
                         + " (--finish sets the line itself)")
        if options.start is None and early:
            s_turn, angle = early[0]
            i0 = int(np.searchsorted(dist, s_turn + UTURN_REACH_M))
            how0 = "u-turn"
            notes.append(f"start set {UTURN_REACH_M:.0f} m after a {angle:.0f} deg U-turn at "
                         f"{s_turn:.0f} m (the roll-out before the start; --start overrides)")
    if options.start is not None:
        i0, how0 = _locate(options.start, dist, elapsed, where, "start"), "override"
    if options.finish is not None:
        i1, how1 = _locate(options.finish, dist, elapsed, where, "finish"), "override"
    if i1 - i0 < 2:
        raise CourseError(f"{where}: the race would start at {dist[i0]:.0f} m and finish at "
                          f"{dist[i1]:.0f} m of the ride: nothing left to fit")
    report = TrimReport(
        ride_length_m=length, start_m=float(dist[i0]), finish_m=float(dist[i1]),
        start_method=how0, finish_method=how1,
        start_elapsed_s=None if elapsed is None else float(elapsed[i0]),
        finish_elapsed_s=None if elapsed is None else float(elapsed[i1]), notes=tuple(notes))
    return track.take(slice(i0, i1 + 1)), report


def _locate(mark: Mark, dist: np.ndarray, elapsed: np.ndarray | None, where: str,
            what: str) -> int:
    if mark.distance_m is not None:
        if not 0.0 <= mark.distance_m <= dist[-1]:
            raise CourseError(f"{where}: {what} {mark} is outside the ride (0 to "
                              f"{dist[-1]:.0f} m along its GPS track)")
        return int(np.argmin(np.abs(dist - mark.distance_m)))
    if elapsed is None:
        raise CourseError(f"{where}: {what} {mark} is a time but the file has no timestamps")
    assert mark.elapsed_s is not None
    if not elapsed[0] - 1.0 <= mark.elapsed_s <= elapsed[-1] + 1.0:
        raise CourseError(f"{where}: {what} {mark} is outside the ride ({elapsed[0]:.0f} to "
                          f"{elapsed[-1]:.0f} s of moving fixes)")
    return int(np.argmin(np.abs(elapsed - mark.elapsed_s)))


def find_uturns(x: np.ndarray, y: np.ndarray, dist: np.ndarray, *,
                reach_m: float = UTURN_REACH_M, gap_m: float = UTURN_GAP_M,
                min_deg: float = UTURN_MIN_DEG) -> list[tuple[float, float]]:
    """Turn-rounds along a track: (distance of the apex, turn in degrees), in order.

    At each point of a 5 m resampling, the chord from `reach_m` before and the chord to
    `reach_m` after; a U-turn has them nearly opposite and its two legs close together.
    """
    if dist[-1] < 4 * reach_m:
        return []
    u = np.arange(0.0, dist[-1], 5.0)
    px, py = np.interp(u, dist, x), np.interp(u, dist, y)
    k = round(reach_m / 5.0)
    ax, ay, bx, by = px[:-2 * k], py[:-2 * k], px[2 * k:], py[2 * k:]
    cx, cy = px[k:-k], py[k:-k]
    v1 = np.column_stack([cx - ax, cy - ay])
    v2 = np.column_stack([bx - cx, by - cy])
    norm = np.linalg.norm(v1, axis=1) * np.linalg.norm(v2, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.where(norm > 1e-6, (v1 * v2).sum(axis=1) / norm, 1.0)
    turn = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    hit = (turn >= min_deg) & (np.hypot(bx - ax, by - ay) <= gap_m)
    out: list[tuple[float, float]] = []
    for run in _runs(hit):
        best = run.start + int(np.argmax(turn[run]))
        out.append((float(u[best + k]), float(turn[best])))
    return out


def _route_match(track: Track, dist: np.ndarray, route: Recording, where: str
                 ) -> tuple[int, int]:
    """Start and finish fix of the race against a route (see the module docstring)."""
    ok = np.isfinite(route.lat_deg) & np.isfinite(route.lon_deg)
    if ok.sum() < 2:
        raise CourseError(f"{route.path}: the route has fewer than 2 positions")
    o = track.origin
    rx, ry, _ = pymap3d.geodetic2enu(route.lat_deg[ok], route.lon_deg[ok],
                                     np.full(int(ok.sum()), o.alt_m), o.lat_deg, o.lon_deg,
                                     o.alt_m)
    rx, ry = np.asarray(rx, float), np.asarray(ry, float)
    r_len = float(np.hypot(np.diff(rx), np.diff(ry)).sum())
    ahead_i = int(np.searchsorted(np.concatenate([[0.0], np.cumsum(np.hypot(
        np.diff(rx), np.diff(ry)))]), min(ROUTE_MATCH_M, r_len / 4)))
    ahead = np.array([rx[ahead_i] - rx[0], ry[ahead_i] - ry[0]])
    x, y = track.x_m, track.y_m
    d0 = np.hypot(x - rx[0], y - ry[0])
    d1 = np.hypot(x - rx[-1], y - ry[-1])
    heading = np.column_stack([np.gradient(x), np.gradient(y)])
    starts = _local_minima(d0, ROUTE_MATCH_M)
    starts = [i for i in starts if float(heading[i] @ ahead) > 0.0]
    if not starts:
        raise CourseError(f"{where}: the ride never passes within {ROUTE_MATCH_M:.0f} m of "
                          f"the start of the route {route.path.name} heading its way")
    finishes = _local_minima(d1, ROUTE_MATCH_M)
    for i0 in reversed(starts):
        for i1 in finishes:
            run = dist[i1] - dist[i0]
            if 0.8 * r_len <= run <= 1.3 * r_len:
                return i0, i1
    raise CourseError(f"{where}: no stretch of the ride runs from the start to the finish of "
                      f"the route {route.path.name} ({r_len / 1000:.2f} km, within 80-130 % "
                      "of its length)")


def _local_minima(d: np.ndarray, within: float) -> list[int]:
    """Index of the closest fix of each pass within `within` of a point."""
    return [run.start + int(np.argmin(d[run])) for run in _runs(d <= within)]


def _runs(mask: np.ndarray) -> list[slice]:
    """The runs of consecutive True in a 1D mask, in order."""
    labels, _ = scipy.ndimage.label(mask)
    return [run for (run,) in scipy.ndimage.find_objects(labels)]

