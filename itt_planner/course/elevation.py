"""Which altitude profile a GPS course gets, and whether it can be trusted.

Sources (`ElevationOptions.source`):

- `device`: the ride's own altitude (barometric or GPS), fitted with the course's normal
  altitude smoothing;
- `smoothed`: the same, smoothed over `smoothed_scale_m` (jittery GPS altitude);
- `route`: the altitude of a route file (a planned GPX, usually from a terrain model),
  placed on the course by projecting each route point onto the centre line;
- `mix`: long waves from the route, short waves from the device (a complementary
  filter at `mix_scale_m`): the route fixes the device's offset and drift, the device
  keeps the detail a terrain model smooths away; where the two still disagree by more
  than `tolerance_m` after that, the route is used;
- `auto`: `mix` when a route with altitude is given, else `device`.

Checks, reported in `Course.build["elevation"]` and shown by `course info`:

- disagreement between device and route (offset, then the largest difference and how
  many metres of course exceed `tolerance_m`): a warning when it exceeds the tolerance;
- suspect grades in the chosen profile: stretches steeper than `steep_grade`, and a
  "dip" or "bump" (a steep descent and a steep climb of about the same height within
  `dip_span_m`), the signature of an altitude error rather than a road (issue 14: a
  device 80 m low over the last 2 km made a -12 % dip and a +16 % wall). A real valley
  can look the same; the flag says where to look, it does not change the profile.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import pymap3d
from scipy.ndimage import gaussian_filter1d, maximum_filter1d
from scipy.spatial import cKDTree

from itt_planner.course.geometry import GeoOrigin
from itt_planner.course.track_files import Recording
from itt_planner.errors import CourseError

SOURCES = ("auto", "device", "smoothed", "route", "mix")
#: Below this share of fixes with an altitude, the interpolation between them is reported.
_MIN_ALTITUDE_SHARE = 0.9


@dataclass(frozen=True)
class ElevationOptions:
    """Choice and checks of the altitude profile (see the module docstring)."""

    source: str = "auto"
    tolerance_m: float = 5.0
    smoothed_scale_m: float = 250.0
    mix_scale_m: float = 1000.0
    mix_margin_m: float = 500.0
    steep_grade: float = 0.15
    dip_grade: float = 0.10
    dip_min_depth_m: float = 15.0
    dip_span_m: float = 2000.0

    def __post_init__(self) -> None:
        if self.source not in SOURCES:
            raise CourseError(f"elevation source {self.source!r}: expected one of "
                              f"{', '.join(SOURCES)}")


#: fit(s of points, z of points, smoothing length m) -> z on the course grid
AltitudeFit = Callable[[np.ndarray, np.ndarray, float], np.ndarray]


def build_profile(s: np.ndarray, x: np.ndarray, y: np.ndarray, origin: GeoOrigin,
                  device: tuple[np.ndarray, np.ndarray], route: Recording | None,
                  options: ElevationOptions, fit: AltitudeFit, scale_m: float,
                  device_share: float = 1.0) -> tuple[np.ndarray, dict[str, Any]]:
    """The chosen z(s) on the grid `s` and the report of every source and check.

    `device` is (arc length, altitude) of the ride's fixes, `device_share` the share of
    them that had an altitude in the file (the rest interpolated); `fit` the course's
    altitude smoothing; `scale_m` its normal smoothing length.

    A track without altitude (none recorded, or one constant value: a route planner's
    export without a terrain model) gives a flat device profile: `auto` then takes the
    route's altitude if there is one, else the flat profile with a warning saying so.

    Raises:
        CourseError: `route` or `mix` asked for without a route that has altitude;
            `device`, `smoothed` or `mix` asked for on a track without altitude.
    """
    missing = _missing_altitude(device[1], device_share)
    profiles: dict[str, np.ndarray] = {
        "device": fit(device[0], device[1], scale_m),
        "smoothed": fit(device[0], device[1], options.smoothed_scale_m),
    }
    warnings: list[str] = []
    if route is not None:
        s_r, z_r = route_on_course(route, s, x, y, origin)
        if len(s_r) >= 5 and s_r.max() - s_r.min() >= 0.5 * (s[-1] - s[0]):
            profiles["route"] = fit(s_r, z_r, scale_m)
        else:
            warnings.append(f"route {route.path.name}: only {len(s_r)} points with altitude "
                            "lie on the course; its altitude is not used")
    source = options.source
    if source == "auto":
        source = ("route" if missing else "mix") if "route" in profiles else "device"
    if source in ("route", "mix") and "route" not in profiles:
        raise CourseError(f"elevation source {source!r} needs a route with altitude on the "
                          "course (--route)")
    if missing and options.source in ("device", "smoothed", "mix"):
        raise CourseError(f"elevation source {options.source!r}: the track has {missing}; "
                          "give a route with altitude (--route, elevation route)")
    if missing and source == "device":
        warnings.append(f"the track has {missing}: the course is FLAT; give a route with "
                        "altitude (--route) for its climbs and descents")
    elif not missing and device_share < _MIN_ALTITUDE_SHARE:
        warnings.append(f"the track has no altitude at {100 * (1 - device_share):.0f} % of "
                        "its fixes: interpolated between the others")
    disagreement = None
    if "route" in profiles and not missing:
        profiles["mix"] = mix_profiles(s, profiles["device"], profiles["route"], options)
        disagreement = compare(s, profiles["device"], profiles["route"], options.tolerance_m)
        if disagreement["max_m"] > options.tolerance_m:
            warnings.append(
                f"device and route altitude disagree by up to {disagreement['max_m']:.0f} m "
                f"(at {disagreement['at_s_m'] / 1000:.2f} km, after removing a "
                f"{disagreement['offset_m']:+.0f} m offset); "
                f"{disagreement['over_tolerance_m']:.0f} m of course beyond "
                f"{options.tolerance_m:.0f} m; using {source}")
    z = profiles[source]
    suspects = suspect_grades(s, z, options)
    warnings.extend(
        f"suspect grade ({f['kind']}) {f['from_s_m'] / 1000:.2f}-{f['to_s_m'] / 1000:.2f} km: "
        f"{f['min_grade'] * 100:.1f} % to {f['max_grade'] * 100:.1f} %"
        + (f", {f['depth_m']:.0f} m deep" if "depth_m" in f else "")
        + " in the " + source + " altitude; check it (--elevation, --route)"
        for f in suspects)
    report = {
        "source": source, "requested": options.source, "tolerance_m": options.tolerance_m,
        "device_altitude": {"share": round(device_share, 4), "missing": missing},
        "profiles": {k: _profile_stats(s, v) for k, v in profiles.items()},
        "disagreement": disagreement, "suspect_grades": suspects, "warnings": warnings,
    }
    return z, report


def _missing_altitude(z: np.ndarray, share: float) -> str | None:
    """Why the track's altitude is no altitude (None if it is one): none recorded, or
    the same value at every fix (a route exported without a terrain model writes 0)."""
    if share == 0:
        return "no altitude"
    if len(z) and float(np.ptp(z)) == 0.0:
        return f"the same altitude ({float(z[0]):.0f} m) at every fix"
    return None


def route_on_course(route: Recording, s: np.ndarray, x: np.ndarray, y: np.ndarray,
                    origin: GeoOrigin, radius_m: float = 40.0
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Arc length on the course and altitude of each route point with altitude.

    Each point goes to the course point within `radius_m` closest to where the previous
    one went plus the step between them, so out-and-back legs are not confused.
    """
    ok = np.isfinite(route.lat_deg) & np.isfinite(route.lon_deg) & np.isfinite(route.ele_m)
    if ok.sum() == 0:
        return np.zeros(0), np.zeros(0)
    rx, ry, _ = pymap3d.geodetic2enu(route.lat_deg[ok], route.lon_deg[ok],
                                     np.full(int(ok.sum()), origin.alt_m), origin.lat_deg,
                                     origin.lon_deg, origin.alt_m)
    rx, ry, rz = np.asarray(rx, float), np.asarray(ry, float), route.ele_m[ok]
    tree = cKDTree(np.column_stack([x, y]))
    hits = tree.query_ball_point(np.column_stack([rx, ry]), radius_m)
    out_s, out_z = [], []
    expect = 0.0
    prev = None
    for k, cand in enumerate(hits):
        if prev is not None:
            expect = prev[0] + float(np.hypot(rx[k] - prev[1], ry[k] - prev[2]))
        if not cand:
            continue
        cs = s[np.asarray(cand)]
        best = float(cs[np.argmin(np.abs(cs - expect))])
        out_s.append(best)
        out_z.append(float(rz[k]))
        prev = (best, rx[k], ry[k])
    return np.asarray(out_s), np.asarray(out_z)


def mix_profiles(s: np.ndarray, z_device: np.ndarray, z_route: np.ndarray,
                 options: ElevationOptions) -> np.ndarray:
    """Route long waves + device short waves; the route where they still disagree."""
    ds = float(s[1] - s[0])
    diff = z_device - z_route
    low = gaussian_filter1d(diff, options.mix_scale_m / ds, mode="nearest")
    mixed = z_device - low
    bad = np.abs(diff - low) > options.tolerance_m
    # The route takes over `mix_margin_m` around each disagreement and the switch is
    # spread over a few hundred metres: a difference of up to `tolerance_m` left at the
    # switch then tilts the profile by a percent or so, not a wall.
    margin = max(1, int(options.mix_margin_m / ds)) * 2 + 1
    weight = gaussian_filter1d(maximum_filter1d(bad.astype(float), margin, mode="nearest"),
                               options.mix_margin_m / 3.0 / ds, mode="nearest")
    weight = np.clip(2.0 * weight, 0.0, 1.0)
    return cast(np.ndarray, (1.0 - weight) * mixed + weight * z_route)


def compare(s: np.ndarray, z_a: np.ndarray, z_b: np.ndarray, tolerance_m: float
            ) -> dict[str, float]:
    """Offset (median a - b), then the largest |a - b - offset|, where, and how much course."""
    diff = z_a - z_b
    offset = float(np.median(diff))
    dev = np.abs(diff - offset)
    i = int(np.argmax(dev))
    ds = float(s[1] - s[0])
    return {"offset_m": round(offset, 1), "max_m": round(float(dev[i]), 1),
            "at_s_m": round(float(s[i]), 1),
            "over_tolerance_m": round(float(np.sum(dev > tolerance_m)) * ds, 1)}


def suspect_grades(s: np.ndarray, z: np.ndarray, options: ElevationOptions
                   ) -> list[dict[str, Any]]:
    """Steep stretches and dip/bump pairs (see the module docstring), in course order."""
    g = np.gradient(z, s)
    out: list[dict[str, Any]] = []
    for a, b in _runs(np.abs(g) > options.steep_grade, s, 10.0):
        out.append({"kind": "steep", "from_s_m": round(float(s[a]), 1),
                    "to_s_m": round(float(s[b]), 1),
                    "min_grade": round(float(g[a:b + 1].min()), 4),
                    "max_grade": round(float(g[a:b + 1].max()), 4)})
    stretches = []
    for sign in (1.0, -1.0):
        for a, b in _runs(sign * g > options.dip_grade, s, 20.0):
            stretches.append((a, b, float(z[b] - z[a])))
    stretches.sort()
    for (a1, b1, dz1), (a2, b2, dz2) in itertools.pairwise(stretches):
        depth = min(abs(dz1), abs(dz2))
        if (dz1 * dz2 < 0 and s[a2] - s[b1] <= options.dip_span_m
                and depth >= options.dip_min_depth_m
                and abs(dz1 + dz2) <= 0.35 * max(abs(dz1), abs(dz2))):
            out.append({"kind": "dip" if dz1 < 0 else "bump",
                        "from_s_m": round(float(s[a1]), 1), "to_s_m": round(float(s[b2]), 1),
                        "min_grade": round(float(g[a1:b2 + 1].min()), 4),
                        "max_grade": round(float(g[a1:b2 + 1].max()), 4),
                        "depth_m": round(depth, 1)})
    out.sort(key=lambda f: f["from_s_m"])
    return out


def _runs(mask: np.ndarray, s: np.ndarray, min_len_m: float) -> list[tuple[int, int]]:
    """Index ranges of True runs at least `min_len_m` long (gaps under 50 m merged)."""
    idx = np.flatnonzero(mask)
    if not len(idx):
        return []
    breaks = np.flatnonzero(np.diff(s[idx]) > 50.0)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    ends = np.concatenate([idx[breaks], [idx[-1]]])
    return [(int(a), int(b)) for a, b in zip(starts, ends, strict=True) if s[b] - s[a] >= min_len_m]


def _profile_stats(s: np.ndarray, z: np.ndarray) -> dict[str, float]:
    g = np.gradient(z, s)
    dz = np.diff(z)
    return {"min_grade": round(float(g.min()), 4), "max_grade": round(float(g.max()), 4),
            "gain_m": round(float(dz[dz > 0].sum()), 1)}
