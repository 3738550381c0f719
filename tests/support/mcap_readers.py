"""Four independent readers of an MCAP ride log, for the tests of every log we write.

`mcap` (raw records), `mcap_ros2` (decodes with its own parser of the embedded
`ros2msg` schema), `rosbags` (`AnyReader` on the bare file, its own schema parser) and
Rerun's MCAP loader (`rerun mcap convert`, then the `.rrd` read back with
`rerun.chunk.RrdReader`). Each returns {topic: (schema name, count)} plus a few decoded
values, so a test can check that all four agree with what was written.
"""

from __future__ import annotations

import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

RERUN = Path(sys.executable).with_name("rerun")


def raw_counts(path: Path) -> dict[str, tuple[str, int]]:
    """Topic -> (schema name, message count) from mcap's plain reader (summary-free)."""
    counts: Counter[tuple[str, str]] = Counter()
    with path.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        for schema, channel, _msg in reader.iter_messages():
            assert schema is not None and schema.encoding == "ros2msg"
            assert channel.message_encoding == "cdr"
            counts[(channel.topic, schema.name)] += 1
    return {topic: (name, n) for (topic, name), n in counts.items()}


def mcap_ros2_messages(path: Path) -> dict[str, list[Any]]:
    """Topic -> decoded messages, by mcap_ros2's own `ros2msg` parser."""
    out: dict[str, list[Any]] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, _msg, decoded in reader.iter_decoded_messages():
            out.setdefault(channel.topic, []).append(decoded)
    return out


def rosbags_messages(path: Path) -> tuple[dict[str, tuple[str, int]], dict[str, list[Any]]]:
    """(topic -> (type, count), topic -> decoded messages) from rosbags' AnyReader."""
    msgs: dict[str, list[Any]] = {}
    with AnyReader([path]) as reader:
        info = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        for conn, _t, raw in reader.messages():
            msgs.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    return info, msgs


def rerun_rows(path: Path, tmp_dir: Path) -> dict[str, list[dict[str, Any]]]:
    """Entity path -> rows (column name -> value) of Rerun's conversion of the log."""
    from rerun.chunk import RrdReader  # heavy: only this reader needs it

    rrd = tmp_dir / f"{path.stem}.rrd"
    subprocess.run([str(RERUN), "mcap", "convert", str(path), "-o", str(rrd)],
                   check=True, capture_output=True, timeout=120)
    rows: dict[str, list[dict[str, Any]]] = {}
    for chunk in RrdReader(rrd).store().stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch().to_pydict()
        names = list(batch)
        for i in range(chunk.num_rows):
            rows.setdefault(chunk.entity_path, []).append({n: batch[n][i] for n in names})
    for entity in rows.values():
        entity.sort(key=lambda r: r["message_log_time"])
    return rows


def check_all_readers(path: Path, expected: dict[str, tuple[str, int]],
                      tmp_dir: Path) -> dict[str, Any]:
    """Assert that the four readers see exactly `expected` (topic -> (type, count)).

    Returns the decoded messages of each reader for value checks.
    """
    assert raw_counts(path) == expected
    ros2 = mcap_ros2_messages(path)
    assert {t: len(m) for t, m in ros2.items()} == {t: n for t, (_, n) in expected.items()}
    info, rosbags_msgs = rosbags_messages(path)
    assert info == expected
    rows = rerun_rows(path, tmp_dir)
    assert {t: len(r) for t, r in rows.items()} == {t: n for t, (_, n) in expected.items()}
    return {"mcap_ros2": ros2, "rosbags": rosbags_msgs, "rerun": rows}


def rerun_value(row: dict[str, Any]) -> Any:
    """The decoded payload of one Rerun row: the reflected message, or the GPS point."""
    for name, value in row.items():
        if name.endswith(":message"):
            return value[0]
    return {"lat_lon": row["GeoPoints:positions"][0], "altitude": row["altitude"][0]}
