"""The sweep's result table on disk: a Parquet dataset directory that only ever gains files.

`results.parquet/` holds one small `part-*.parquet` per batch of finished cases. A part is
written to a hidden temporary name and renamed into place (atomic on POSIX), so an
interrupted sweep leaves only whole parts, and any Parquet reader (`pyarrow`,
`pandas.read_parquet`, DuckDB) reads the directory as one table. A resumed sweep reads
the keys already recorded and does not solve them again. `compact` merges the parts
into one when a sweep completes; if it is interrupted between writing the merged part
and deleting the old ones, `read` keeps one row per key (the latest), so nothing is
counted twice.
"""

from __future__ import annotations

import time
import uuid
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from itt_planner.errors import IttError

#: Columns of the table (SI units); figures are null for a case that failed.
SCHEMA = pa.schema([
    ("key", pa.string()), ("sweep", pa.string()), ("status", pa.string()),
    ("solver_status", pa.string()), ("reason", pa.string()),
    ("course", pa.string()), ("course_length_m", pa.float64()), ("rider", pa.string()),
    ("equipment", pa.string()), ("model", pa.string()), ("wprime_model", pa.string()),
    ("wind_speed_mps", pa.float64()), ("wind_from_rad", pa.float64()), ("mu", pa.float64()),
    ("mass_kg", pa.float64()), ("drag_area_m2", pa.float64()),
    ("critical_power_w", pa.float64()), ("w_prime_j", pa.float64()),
    ("finish_time_s", pa.float64()), ("mean_power_w", pa.float64()),
    ("w_prime_end_j", pa.float64()), ("w_prime_min_j", pa.float64()),
    ("split_s_m", pa.list_(pa.float64())), ("split_elapsed_s", pa.list_(pa.float64())),
    ("iterations", pa.int64()), ("n_nodes", pa.int64()), ("solve_time_s", pa.float64()),
    ("build_time_s", pa.float64()), ("case_wall_s", pa.float64()),
    ("node_id", pa.string()), ("hostname", pa.string()), ("pid", pa.int64()),
    ("worker_cases", pa.int64()), ("worker_peak_rss_mb", pa.float64()),
    ("finished_unix_s", pa.float64()),
])
PART_GLOB = "part-*.parquet"


class ResultStoreError(IttError):
    """The result dataset cannot be read or written (names the path)."""


class ResultStore:
    """Append-only Parquet dataset of sweep results (module docstring)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if self.path.exists() and not self.path.is_dir():
            msg = (f"{self.path}: is a file; sweep results are a Parquet dataset directory "
                   "(give a new name, e.g. results.parquet)")
            raise ResultStoreError(msg)

    def parts(self) -> list[Path]:
        return sorted(self.path.glob(PART_GLOB)) if self.path.is_dir() else []

    def append(self, rows: list[dict[str, Any]]) -> Path | None:
        """Write `rows` as one new part (atomically); None if there are none."""
        if not rows:
            return None
        table = pa.Table.from_pylist([{name: row.get(name) for name in SCHEMA.names}
                                      for row in rows], schema=SCHEMA)
        name = f"part-{time.time_ns():020d}-{uuid.uuid4().hex[:8]}.parquet"
        return self._write(table, name)

    def _write(self, table: pa.Table, name: str) -> Path:
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            tmp = self.path / f".{name}.tmp"
            pq.write_table(table, tmp)
            tmp.replace(self.path / name)
        except OSError as err:
            raise ResultStoreError(f"{self.path}: cannot write results ({err})") from None
        return self.path / name

    def read_raw(self) -> pa.Table:
        """Every row of every part, duplicates included (empty table if none)."""
        parts = self.parts()
        if not parts:
            return SCHEMA.empty_table()
        try:
            return pa.concat_tables([pq.read_table(p, schema=SCHEMA) for p in parts])
        except (OSError, pa.ArrowException) as err:
            raise ResultStoreError(f"{self.path}: cannot read results ({err})") from None

    def read(self) -> pa.Table:
        """The results, one row per case key (the latest when a case was re-run)."""
        table = self.read_raw()
        if table.num_rows == 0:
            return table
        table = table.sort_by([("finished_unix_s", "descending")])
        keys = table.column("key").to_pylist()
        first: dict[str, int] = {}
        for i, key in enumerate(keys):
            first.setdefault(key, i)
        latest = table.take(sorted(first.values()))
        return latest.sort_by([("finished_unix_s", "ascending")])

    def recorded(self, *, statuses: tuple[str, ...] | None = None) -> set[str]:
        """Keys already recorded (with one of `statuses`, if given)."""
        table = self.read()
        if statuses is not None:
            table = table.filter(pc.is_in(table.column("status"), pa.array(statuses)))
        return set(table.column("key").to_pylist())

    def compact(self) -> Path | None:
        """Merge all parts into one (write first, then delete the old parts)."""
        parts = self.parts()
        if len(parts) <= 1:
            return parts[0] if parts else None
        merged = self._write(self.read(), f"part-{time.time_ns():020d}-merged.parquet")
        for part in parts:
            part.unlink(missing_ok=True)
        return merged
