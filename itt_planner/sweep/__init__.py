"""Scenario sweeps on Ray: many full-course plans (riders x wind x grip x equipment x model).

The stages, one module each:

- `spec`: the YAML sweep spec as frozen, validated dataclasses (`load_spec`, `SweepSpec`);
- `cases`: the spec expanded into cases keyed by a hash of their inputs (`expand`);
- `solve`: one case -> one result row, never raising (`solve_case`), and the Ray actor
  that solves cases on a worker (`CaseSolver`);
- `store`: the append-only Parquet result dataset a sweep resumes from (`ResultStore`);
- `cluster`: a private Ray instance on 127.0.0.1, or an existing cluster (`ray_session`);
- `runner`: cases to actors, rows to the store, progress (`run_sweep`);
- `report`: the static HTML report of a result table (`write_sweep_report`);
- `calibrate_many`: many riders' ride folders calibrated in parallel on the same Ray
  engine (`calibrate_many`).

Ray is imported only inside `cluster` and the workers, so the spec, cases and store
work without it.
"""

from itt_planner.sweep.calibrate_many import RiderRides, calibrate_many, calibrate_rider
from itt_planner.sweep.cases import Case, expand, load_inputs
from itt_planner.sweep.cluster import RayClusterError, RaySession, ray_session
from itt_planner.sweep.report import write_sweep_report
from itt_planner.sweep.runner import SweepSummary, run_sweep
from itt_planner.sweep.solve import CONVERGED, FAILED, NOT_CONVERGED, CaseSolver, solve_case
from itt_planner.sweep.spec import Equipment, Grid, SweepSpec, SweepSpecError, load_spec, parse_spec
from itt_planner.sweep.store import SCHEMA, ResultStore, ResultStoreError

__all__ = [
    "CONVERGED", "FAILED", "NOT_CONVERGED", "SCHEMA", "Case", "CaseSolver", "Equipment", "Grid",
    "RayClusterError", "RaySession", "ResultStore", "ResultStoreError", "RiderRides",
    "SweepSpec", "SweepSpecError", "SweepSummary", "calibrate_many", "calibrate_rider",
    "expand", "load_inputs", "load_spec", "parse_spec", "ray_session", "run_sweep",
    "solve_case", "write_sweep_report",
]
