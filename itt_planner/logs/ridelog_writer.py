"""Writing MCAP ride logs (the format: `ridelog`): inputs, advice and diagnostics.

Each channel gets the full `.msg` definition as its `ros2msg` schema and the QoS its
publishers offered (the interface's for our topics); messages are logged at their header
stamp. Chunks are closed by size and by log time, so a crash loses little.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from types import TracebackType
from typing import IO, Any, cast

from mcap.writer import CompressionType, Writer

from itt_msgs_py import DEFAULT_NAMESPACE, msgdef, registry, serialize, topics
from itt_msgs_py.convert import (
    advice_to_msg,
    diagnostics_to_msg,
    from_time,
    stamp_ns,
    target_line_msg,
    target_power_msg,
)
from itt_msgs_py.qos import OFFERED_QOS_KEY, offered_qos_yaml
from itt_planner.errors import RideLogError
from itt_planner.live.advice import Advice, Diagnostic
from itt_planner.live.samples import Sample
from itt_planner.logs.ridelog import (
    MESSAGE_ENCODING,
    METADATA_NAME,
    PROFILE,
    SCHEMA_ENCODING,
    RawRecord,
)

#: A chunk is closed (and the file flushed) at this size or after `CHUNK_PERIOD_S` of log
#: time, whichever comes first: a crash loses at most one chunk, i.e. half a minute of a
#: 1 Hz ride, while zstd still has enough in a chunk to pack it well.
CHUNK_SIZE_BYTES = 256 * 1024
CHUNK_PERIOD_S = 30.0


@dataclass(frozen=True)
class RideMetadata:
    """Where a ride log comes from (the `itt_ride` metadata record).

    `air_temperature_c` is the median of the recorded ride's air temperatures (NaN when
    it has none, and then left out of the record): a replay's warning about the air its
    plan assumes gives the day's.
    """

    source: str = ""
    sha256: str = ""
    device: str = ""
    rider: str = ""
    air_temperature_c: float = math.nan

    def as_record(self) -> dict[str, str]:
        """The metadata record's string map."""
        return {k: str(v) for k, v in asdict(self).items()
                if not (isinstance(v, float) and math.isnan(v))}

    @classmethod
    def from_record(cls, record: Mapping[str, str]) -> RideMetadata:
        """The record `as_record` wrote (fields it lacks, or cannot be read, at their
        defaults: a log from before a field existed, or another tool's)."""
        kwargs: dict[str, Any] = {}
        for f in fields(cls):
            if f.name in record:
                try:
                    kwargs[f.name] = cast(type[Any], type(f.default))(record[f.name])
                except ValueError:
                    continue
        return cls(**kwargs)


class RideLogWriter:
    """Write a ride log; use as a context manager so the file is finished even on errors.

    Args:
        path: the `.mcap` file to create (overwritten).
        metadata: the `itt_ride` record, written first so a cut-off file still has it.
        namespace: ROS namespace of the pacing topics.

    Raises:
        RideLogError: the file cannot be created.
    """

    def __init__(self, path: str | Path, *, metadata: RideMetadata | None = None,
                 namespace: str = DEFAULT_NAMESPACE,
                 compression: CompressionType = CompressionType.ZSTD) -> None:
        self.path = Path(path)
        self.namespace = namespace
        self._topics = registry.topics_by_name(namespace)
        self.counts: Counter[str] = Counter()
        try:
            self._file: IO[bytes] = self.path.open("wb")
        except OSError as err:
            raise RideLogError(f"{self.path}: cannot create the ride log ({err})") from None
        self._writer = Writer(self._file, chunk_size=CHUNK_SIZE_BYTES, compression=compression)
        self._writer.start(profile=PROFILE, library="itt-planner")
        self._schemas: dict[tuple[str, str, bytes], int] = {}
        self._channels: dict[tuple[str, int, str], int] = {}
        self._sequence: Counter[int] = Counter()
        self._chunk_start_ns: int | None = None
        self._closed = False
        if metadata is not None:
            self._writer.add_metadata(METADATA_NAME, metadata.as_record())

    def __enter__(self) -> RideLogWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Write the summary (indexes, statistics) and close the file; idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()  # type: ignore[no-untyped-call]
        finally:
            self._file.close()

    def _channel(self, topic: str, msgtype: str, schema_encoding: str, schema_data: bytes,
                 message_encoding: str, offered_qos: str = "") -> int:
        """The channel id; a new channel carries `offered_qos`, or without it the
        interface's QoS when `topic` is one of ours."""
        schema_key = (msgtype, schema_encoding, schema_data)
        schema_id = self._schemas.get(schema_key)
        if schema_id is None:
            schema_id = self._writer.register_schema(msgtype, schema_encoding, schema_data)
            self._schemas[schema_key] = schema_id
        channel_key = (topic, schema_id, message_encoding)
        channel_id = self._channels.get(channel_key)
        if channel_id is None:
            if not offered_qos and (known := self._topics.get(topic)) is not None:
                offered_qos = offered_qos_yaml(known.qos)
            channel_id = self._writer.register_channel(
                topic, message_encoding, schema_id, metadata={OFFERED_QOS_KEY: offered_qos})
            self._channels[channel_key] = channel_id
        return channel_id

    def add_metadata(self, name: str, record: dict[str, str]) -> None:
        """Write a metadata record (string map)."""
        self._writer.add_metadata(name, {k: str(v) for k, v in record.items()})

    def write_raw(self, record: RawRecord) -> None:
        """Copy a stored message as it is (schema, encoding, times and bytes)."""
        channel_id = self._channel(record.topic, record.msgtype, record.schema_encoding,
                                   record.schema_data, record.message_encoding,
                                   record.offered_qos_profiles)
        self._add(channel_id, record.topic, record.log_time_ns, record.publish_time_ns,
                  record.data)

    def write_msg(self, topic: topics.Topic, msg: Any) -> None:
        """Write a message object on `topic`, logged at its header stamp."""
        time_ns = stamp_ns(from_time(msg.header.stamp))
        name = topic.name(self.namespace)
        channel_id = self._channel(name, topic.msgtype, SCHEMA_ENCODING,
                                   msgdef(topic.msgtype).encode(), MESSAGE_ENCODING)
        self._add(channel_id, name, time_ns, time_ns, serialize(msg))

    def write_sample(self, sample: Sample) -> None:
        """Write an input sample on its topic (the sample registry's converter)."""
        self.write_msg(*registry.sample_to_msg(sample))

    def write_advice(self, advice: Advice) -> None:
        """Write an advice on `advice`, `target_power` and `target_line`."""
        self.write_msg(topics.ADVICE, advice_to_msg(advice))
        self.write_msg(topics.TARGET_POWER, target_power_msg(advice))
        self.write_msg(topics.TARGET_LINE, target_line_msg(advice))

    def write_diagnostics(self, diagnostics: list[Diagnostic], stamp_s: float) -> None:
        """Write the engine's health items as one `DiagnosticArray`."""
        self.write_msg(topics.DIAGNOSTICS, diagnostics_to_msg(diagnostics, stamp_s))

    def _add(self, channel_id: int, topic: str, log_time_ns: int, publish_time_ns: int,
             data: bytes) -> None:
        if self._closed:
            raise RideLogError(f"{self.path}: write after close")
        if self._chunk_start_ns is None:
            self._chunk_start_ns = log_time_ns
        elif log_time_ns - self._chunk_start_ns >= CHUNK_PERIOD_S * 1e9:
            self._writer.flush()  # type: ignore[no-untyped-call]  # ends the chunk, flushes
            self._chunk_start_ns = log_time_ns
        self._writer.add_message(channel_id, log_time=log_time_ns, data=data,
                                 publish_time=publish_time_ns,
                                 sequence=self._sequence[channel_id])
        self._sequence[channel_id] += 1
        self.counts[topic] += 1
