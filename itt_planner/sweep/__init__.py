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

import lazy_loader

# Public names load on first use, from `__init__.pyi` (why: itt_planner/__init__.py).
__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
