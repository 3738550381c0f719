"""Type stub of `itt_planner.sweep`: its public names, loaded lazily by `__init__.py`."""

from .calibrate_many import RiderRides, calibrate_many, calibrate_rider
from .cases import Case, expand, load_inputs
from .cluster import RayClusterError, RaySession, ray_session
from .report import write_sweep_report
from .runner import SweepSummary, run_sweep
from .solve import CONVERGED, FAILED, NOT_CONVERGED, CaseSolver, solve_case
from .spec import Equipment, Grid, SweepSpec, SweepSpecError, load_spec, parse_spec
from .store import SCHEMA, ResultStore, ResultStoreError

__all__ = [
    "CONVERGED", "FAILED", "NOT_CONVERGED", "SCHEMA", "Case", "CaseSolver", "Equipment", "Grid",
    "RayClusterError", "RaySession", "ResultStore", "ResultStoreError", "RiderRides",
    "SweepSpec", "SweepSpecError", "SweepSummary", "calibrate_many", "calibrate_rider",
    "expand", "load_inputs", "load_spec", "parse_spec", "ray_session", "run_sweep",
    "solve_case", "write_sweep_report",
]
