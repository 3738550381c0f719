"""Stage 1, the road: a `Course` (s, curvature, slope, heights, widths, ENU <-> lat/lon)
from a GPS track (GPX/FIT/TCX/CSV), a course-builder YAML or a demo course.

Track files are read (`track_files`), cleaned (`track_clean`), trimmed to the race
(`trim`), given an elevation profile (`elevation`) and fitted (`fit`); `loader` picks the
path by file type; `builder` makes courses from segments; `geometry` is the `Course` itself;
`racing_line` is the shortest line within the road and the course along it.
"""

import lazy_loader

# Public names load on first use, from `__init__.pyi` (why: itt_planner/__init__.py).
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
