"""Stage 1, the road: a `Course` (s, curvature, slope, heights, widths, ENU <-> lat/lon)
from a GPS track (GPX/FIT/TCX/CSV), a course-builder YAML or a demo course.

Track files are read (`track_files`), cleaned (`track_clean`), trimmed to the race
(`trim`), given an elevation profile (`elevation`) and fitted (`fit`); `loader` picks the
path by file type; `builder` makes courses from segments; `geometry` is the `Course` itself;
`racing_line` is the shortest line within the road and the course along it.
"""

from itt_planner.course.geometry import Corner, Course, GeoOrigin, detect_corners
from itt_planner.course.loader import DEMO_COURSES, demo_path, gps_course_options, load_course

__all__ = ["DEMO_COURSES", "Corner", "Course", "GeoOrigin", "demo_path", "detect_corners",
           "gps_course_options", "load_course"]
