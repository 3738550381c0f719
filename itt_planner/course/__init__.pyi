"""Type stub of `itt_planner.course`: its public names, loaded lazily by `__init__.py`."""

from .geometry import Corner, Course, GeoOrigin, detect_corners
from .loader import DEMO_COURSES, demo_path, gps_course_options, load_course

__all__ = ["DEMO_COURSES", "Corner", "Course", "GeoOrigin", "demo_path", "detect_corners",
           "gps_course_options", "load_course"]
