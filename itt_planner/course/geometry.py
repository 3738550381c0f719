"""The `Course`: a road centre line parametrised by arc length (model.md section 1).

Holds, on a uniform grid in `s`, the ENU centre line anchored at the start, heading
`theta(s)`, curvature `kappa(s)`, altitude `z(s)`, slope `beta(s)` and usable half-widths
`w_L(s)`, `w_R(s)`; the geodetic origin for ENU <-> lat/lon; the detected corners; and
the source file's hash. Saved as one `.npz` file (arrays + a JSON header).

Building a course from a GPS track lives in `course_fit`, from segment descriptions in
`course_builder`; `load_course` resolves any `--course` argument.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
import pymap3d

from itt_planner.errors import CourseError

COURSE_SUFFIX = ".course.npz"
DEFAULT_HALF_WIDTH_M = 4.0
#: Full road width (m) of a GPS course unless set per course or stretch: a closed-road
#: time trial on a two-lane road, where the rider has the whole carriageway (2 x 3.0 m
#: lanes, the common lane width of European secondary roads; main roads have 3.25-3.5 m,
#: narrow country roads 5-5.5 m in all). The GPS trace is taken as the centre line; the
#: OCP keeps its own edge margin (C11) inside this width.
GPS_ROAD_WIDTH_M = 6.0
#: A bend whose radius goes below this is a corner (m).
CORNER_RADIUS_M = 100.0
#: ... and it must turn at least this much in total (rad) to count.
CORNER_MIN_ANGLE_RAD = math.radians(20.0)
_FORMAT_VERSION = 2


@dataclass(frozen=True)
class GeoOrigin:
    """Geodetic anchor of the ENU frame (WGS84)."""

    lat_deg: float
    lon_deg: float
    alt_m: float


@dataclass(frozen=True)
class Corner:
    """One corner. Angles in rad; direction is 'left' (kappa > 0) or 'right'."""

    apex_s_m: float
    entry_s_m: float
    exit_s_m: float
    min_radius_m: float
    angle_rad: float
    direction: str


_ARRAYS = ("s_m", "x_m", "y_m", "z_m", "theta_rad", "kappa_per_m", "beta_rad",
           "width_left_m", "width_right_m")


@dataclass(frozen=True, eq=False)
class Course:
    """A course on a uniform arc-length grid. All arrays have the same length."""

    name: str
    s_m: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    z_m: np.ndarray
    theta_rad: np.ndarray
    kappa_per_m: np.ndarray
    beta_rad: np.ndarray
    width_left_m: np.ndarray
    width_right_m: np.ndarray
    origin: GeoOrigin
    closed_loop: bool
    corners: tuple[Corner, ...]
    source: str = ""
    source_sha256: str = ""
    synthetic: bool = False
    #: How a GPS course was made (trim, altitude source and checks, road width, warnings);
    #: JSON-able, saved with the course, shown by `course info`. Empty for built courses.
    build: dict[str, Any] = field(default_factory=dict)

    # ---- construction -------------------------------------------------------------
    @classmethod
    def from_centerline(
        cls, name: str, x_m: np.ndarray, y_m: np.ndarray, z_m: np.ndarray, *,
        origin: GeoOrigin, closed_loop: bool = False, ds_m: float = 1.0,
        width_left_m: float | np.ndarray = DEFAULT_HALF_WIDTH_M,
        width_right_m: float | np.ndarray = DEFAULT_HALF_WIDTH_M,
        theta_rad: np.ndarray | None = None, kappa_per_m: np.ndarray | None = None,
        source: str = "", source_sha256: str = "", synthetic: bool = False,
        build: dict[str, Any] | None = None,
    ) -> Course:
        """Resample an already smooth ENU centre line to a uniform `ds_m` grid.

        Heading, curvature and slope are derived here (model.md section 1) so every
        builder shares one definition, unless the builder knows heading and curvature
        analytically (spline fit, clothoids) and passes them. Width, heading and curvature
        arrays, if given, are per input point.

        Raises:
            CourseError: fewer than 3 distinct points or shorter than 3 grid steps.
        """
        x, y, z = (np.asarray(a, dtype=float) for a in (x_m, y_m, z_m))
        per_point = {
            "wl": np.broadcast_to(np.asarray(width_left_m, dtype=float), x.shape),
            "wr": np.broadcast_to(np.asarray(width_right_m, dtype=float), x.shape),
        }
        if theta_rad is not None:
            per_point["theta"] = np.unwrap(np.asarray(theta_rad, dtype=float))
        if kappa_per_m is not None:
            per_point["kappa"] = np.asarray(kappa_per_m, dtype=float)
        keep = np.concatenate([[True], np.hypot(np.diff(x), np.diff(y)) > 1e-6])
        x, y, z = x[keep], y[keep], z[keep]
        per_point = {k: v[keep] for k, v in per_point.items()}
        s_in = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
        if len(x) < 3 or s_in[-1] <= 3 * ds_m:
            msg = f"course {name!r}: centre line too short ({s_in[-1]:.1f} m, {len(x)} points)"
            raise CourseError(msg)
        n = math.floor(s_in[-1] / ds_m + 1e-9) + 1
        s = np.linspace(0.0, (n - 1) * ds_m, n)
        xs, ys, zs = (np.interp(s, s_in, a) for a in (x, y, z))
        wl, wr = (np.interp(s, s_in, per_point[k]) for k in ("wl", "wr"))
        if "theta" in per_point:
            theta = np.interp(s, s_in, per_point["theta"])
        else:
            theta = np.unwrap(np.arctan2(np.gradient(ys, s), np.gradient(xs, s)))
        if "kappa" in per_point:
            kappa = np.interp(s, s_in, per_point["kappa"])
        else:
            kappa = np.gradient(theta, s)
        beta = np.arctan(np.gradient(zs, s))
        return cls(
            name=name, s_m=s, x_m=xs, y_m=ys, z_m=zs, theta_rad=theta, kappa_per_m=kappa,
            beta_rad=beta, width_left_m=wl, width_right_m=wr, origin=origin,
            closed_loop=closed_loop, corners=detect_corners(s, kappa), source=source,
            source_sha256=source_sha256, synthetic=synthetic, build=build or {},
        )

    # ---- queries --------------------------------------------------------------------
    @property
    def length_m(self) -> float:
        return float(self.s_m[-1])

    @property
    def ds_m(self) -> float:
        return float(self.s_m[1] - self.s_m[0])

    @property
    def mean_altitude_m(self) -> float:
        """Mean altitude above sea level (`z_m` against `origin`: see `to_geodetic`)."""
        return self.origin.alt_m + float(np.mean(self.z_m) - self.z_m[0])

    @property
    def recorded_air_temperature_c(self) -> float:
        """The median air temperature of the ride the course was built from (NaN when
        it recorded none, or the course is not a ride's)."""
        value = self.build.get("air_temperature_c")
        return math.nan if value is None else float(value)

    def at(self, field: str, s_m: float | np.ndarray) -> np.ndarray:
        """Linear interpolation of one of the arrays (by attribute name) at `s_m`."""
        return cast(np.ndarray, np.interp(s_m, self.s_m, getattr(self, field)))

    def enu_at(self, s_m: float | np.ndarray, n_m: float | np.ndarray = 0.0
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """ENU point at arc length `s_m` and lateral offset `n_m` (positive left)."""
        theta = self.at("theta_rad", s_m)
        x = self.at("x_m", s_m) - np.asarray(n_m) * np.sin(theta)
        y = self.at("y_m", s_m) + np.asarray(n_m) * np.cos(theta)
        return x, y, self.at("z_m", s_m)

    def to_geodetic(self, x_m: float | np.ndarray, y_m: float | np.ndarray,
                    z_m: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """ENU (m) -> WGS84 latitude, longitude (deg) and altitude (m).

        `x_m`, `y_m` are on the origin's tangent plane and `z_m` is altitude, on a scale
        that starts at the origin's altitude at the start: a GPS course's `z_m` is the
        altitude itself, a built course's starts at 0. (Taken as ENU up, a GPS course's
        altitude counted twice, and a point 10 km away at the origin's altitude lies 8 m
        under the tangent plane.)"""
        o = self.origin
        lat, lon, _ = pymap3d.enu2geodetic(x_m, y_m, 0.0 * np.asarray(x_m), o.lat_deg,
                                           o.lon_deg, o.alt_m)
        return lat, lon, o.alt_m + np.asarray(z_m) - self.z_m[0]

    def from_geodetic(self, lat_deg: float | np.ndarray, lon_deg: float | np.ndarray,
                      alt_m: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """WGS84 latitude, longitude (deg), altitude (m) -> ENU (m): the inverse of
        `to_geodetic`, `z` on the course's `z_m` scale."""
        o = self.origin
        x, y, _ = pymap3d.geodetic2enu(lat_deg, lon_deg, o.alt_m + 0.0 * np.asarray(lat_deg),
                                       o.lat_deg, o.lon_deg, o.alt_m)
        return x, y, np.asarray(alt_m) - o.alt_m + self.z_m[0]

    def summary(self) -> dict[str, Any]:
        """The figures `itt-planner course info` prints (edge units: %, deg)."""
        dz = np.diff(self.z_m)
        grade = np.tan(self.beta_rad)
        w = self.width_left_m + self.width_right_m
        radii = [c.min_radius_m for c in self.corners]
        return {
            "name": self.name,
            "length_m": round(self.length_m, 1),
            "gain_m": round(float(dz[dz > 0].sum()), 1),
            "loss_m": round(abs(float(dz[dz < 0].sum())), 1),  # abs: never -0.0
            "max_grade": round(float(grade.max()), 4),
            "min_grade": round(float(grade.min()), 4),
            "n_corners": len(self.corners),
            "min_radius_m": round(min(radii), 1) if radii else None,
            "closed_loop": self.closed_loop,
            "synthetic": self.synthetic,
            "source": self.source,
            "source_sha256": self.source_sha256,
            "road_width_m": [round(float(w.min()), 2), round(float(w.max()), 2)],
            "build": self.build,
            "warnings": list(self.build.get("warnings", [])) + self._loop_warnings(),
            "corners": [
                {"apex_s_m": round(c.apex_s_m, 1), "entry_s_m": round(c.entry_s_m, 1),
                 "exit_s_m": round(c.exit_s_m, 1), "min_radius_m": round(c.min_radius_m, 1),
                 "angle_deg": round(math.degrees(c.angle_rad), 1), "direction": c.direction}
                for c in self.corners
            ],
        }

    def _loop_warnings(self) -> list[str]:
        """A "corner" that turns a full circle or more is no road: GPS wandering while
        the rider stood, or a loop ridden round a car park (a walk at an airport in
        GoldenCheetah's tests made one of 779 deg at R 4.5 m, without a word)."""
        return [f"a corner at {c.apex_s_m:.0f} m turns {math.degrees(c.angle_rad):.0f} deg "
                f"(R {c.min_radius_m:.1f} m): a full circle or more is no road (GPS wander "
                "while standing, or a loop ridden round); trim it off (--start/--finish) or "
                "check the file" for c in self.corners if abs(c.angle_rad) >= 2 * math.pi]

    def laps(self, n: int) -> Course:
        """This closed loop ridden `n` times, as one course (a circuit time trial: the
        route planner's file is one lap); widths and corners repeat, the build records
        `laps`. One lap is the course itself.

        Raises:
            CourseError: `n` below 1, or more than one lap of a course that is no loop.
        """
        if n == 1:
            return self
        if n < 1 or not self.closed_loop:
            why = "at least 1" if n < 1 else "a closed loop, and this course is point to point"
            raise CourseError(f"course {self.name!r}: {n} laps need {why}")
        seam = float(np.hypot(self.x_m[0] - self.x_m[-1], self.y_m[0] - self.y_m[-1]))
        lap_m = self.length_m + seam
        # A grid that ends on its start point would repeat that point at each lap's start.
        body = slice(0, -1) if seam < 1e-6 else slice(None)
        turn = 2 * math.pi * round(float(self.theta_rad[-1] - self.theta_rad[0]) / (2 * math.pi))

        def tiled(a: np.ndarray, step: float = 0.0) -> np.ndarray:
            return np.concatenate([a[body] + k * step for k in range(n - 1)]
                                  + [a + (n - 1) * step])

        return Course.from_centerline(
            self.name, tiled(self.x_m), tiled(self.y_m), tiled(self.z_m), origin=self.origin,
            closed_loop=True, ds_m=self.ds_m, theta_rad=tiled(self.theta_rad, turn),
            kappa_per_m=tiled(self.kappa_per_m), width_left_m=tiled(self.width_left_m),
            width_right_m=tiled(self.width_right_m), source=self.source,
            source_sha256=self.source_sha256, synthetic=self.synthetic,
            build={**self.build, "laps": {"laps": n, "lap_m": round(lap_m, 1)}})

    # ---- persistence ------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write the course as `.course.npz` (arrays + JSON header)."""
        path = Path(path)
        header = {
            "format": "itt-planner-course", "version": _FORMAT_VERSION, "name": self.name,
            "origin": asdict(self.origin), "closed_loop": self.closed_loop,
            "corners": [asdict(c) for c in self.corners], "source": self.source,
            "source_sha256": self.source_sha256, "synthetic": self.synthetic,
            "build": self.build,
        }
        with path.open("wb") as fh:
            np.savez_compressed(fh, header=np.array(json.dumps(header)),
                                **{k: getattr(self, k) for k in _ARRAYS})
        return path

    @classmethod
    def load(cls, path: str | Path) -> Course:
        """Read a course written by `save`.

        Raises:
            CourseError: not a course file, or a missing array.
        """
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                header = json.loads(str(data["header"]))
                arrays = {k: np.array(data[k]) for k in _ARRAYS}
        except (OSError, ValueError, KeyError) as err:
            raise CourseError(f"{path}: not an itt-planner course file ({err})") from None
        if header.get("format") != "itt-planner-course":
            raise CourseError(f"{path}: not an itt-planner course file")
        return cls(
            name=header["name"], origin=GeoOrigin(**header["origin"]),
            closed_loop=header["closed_loop"],
            corners=tuple(Corner(**c) for c in header["corners"]), source=header["source"],
            source_sha256=header["source_sha256"], synthetic=header["synthetic"],
            build=header.get("build", {}), **arrays,
        )


def detect_corners(s_m: np.ndarray, kappa_per_m: np.ndarray) -> tuple[Corner, ...]:
    """Corners are runs where the radius drops below `CORNER_RADIUS_M`.

    A run that turns less than `CORNER_MIN_ANGLE_RAD` (a kink of the road, not a corner)
    is dropped. Consecutive runs of opposite sign (an S-bend) are separate corners. Entry
    and exit are where |kappa| falls to half of the threshold, so the whole bend is timed;
    runs of one sign that this joins (a double apex) are one corner, its apex the
    tightest (each was listed with the whole bend's angle: a 149 deg bend as two of
    149 deg, overlapping).
    """
    kappa = np.asarray(kappa_per_m)
    sign = np.sign(kappa)
    tight = np.abs(kappa) > 1.0 / CORNER_RADIUS_M
    corners: list[Corner] = []
    i, n = 0, len(kappa)
    while i < n:
        if not tight[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and tight[j + 1] and sign[j + 1] == sign[i]:
            j += 1
        a, b = i, j
        while a > 0 and abs(kappa[a - 1]) > 0.5 / CORNER_RADIUS_M and sign[a - 1] == sign[i]:
            a -= 1
        while b + 1 < n and abs(kappa[b + 1]) > 0.5 / CORNER_RADIUS_M and sign[b + 1] == sign[i]:
            b += 1
        angle = float(np.trapezoid(kappa[a:b + 1], s_m[a:b + 1])) if b > a else 0.0
        if abs(angle) >= CORNER_MIN_ANGLE_RAD:
            apex = i + int(np.argmax(np.abs(kappa[i:b + 1])))
            corners.append(Corner(
                apex_s_m=float(s_m[apex]), entry_s_m=float(s_m[a]), exit_s_m=float(s_m[b]),
                min_radius_m=float(1.0 / abs(kappa[apex])), angle_rad=abs(angle),
                direction="left" if kappa[apex] > 0 else "right",
            ))
        i = b + 1
    return tuple(corners)
