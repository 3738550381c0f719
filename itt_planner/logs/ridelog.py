"""MCAP ride logs: write and read the pacing topics as a ROS 2 bag (`cdr` + `ros2msg`).

A ride log is a single `.mcap` file that `ros2 bag play`, Foxglove, rosbags and Rerun
open as they are: each channel carries the full concatenated `.msg` definition as its
schema and the QoS its publishers offered (`offered_qos_profiles`, as rosbag2 records
it, so `ros2 bag play` offers sensors best-effort again), each message the CDR payload,
and log time = publish time = the message's header stamp (the ride clock). A metadata
record `itt_ride` names the source file, its SHA-256, the device and the rider.

Reading streams the file record by record, so a log cut short by a crash or damaged in
the middle still gives back every message before the damage (and after a corrupted
chunk, the chunks that follow): the problems are collected and raised as one
`RideLogError` naming the file once everything readable has been yielded.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from types import TracebackType
from typing import IO, Any, NamedTuple

from mcap.exceptions import InvalidMagic
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from itt_msgs_py import DEFAULT_NAMESPACE, msgdef, serialize, topics, typestore
from itt_msgs_py.convert import (
    advice_to_msg,
    diagnostics_to_msg,
    from_time,
    msg_to_core,
    sample_to_msg,
    stamp_ns,
    target_line_msg,
    target_power_msg,
)
from itt_msgs_py.qos import OFFERED_QOS_KEY, offered_qos_yaml
from itt_planner.live.advice import Advice, Diagnostic
from itt_planner.errors import RideLogError
from itt_planner.live.samples import Sample

log = logging.getLogger(__name__)

#: The MCAP metadata record a ride session (node or replay) writes about itself.
SESSION_METADATA = "itt_replay"
METADATA_NAME = "itt_ride"
PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
#: A chunk is closed (and the file flushed) at this size or after `CHUNK_PERIOD_S` of log
#: time, whichever comes first: a crash loses at most one chunk, i.e. half a minute of a
#: 1 Hz ride, while zstd still has enough in a chunk to pack it well.
CHUNK_SIZE_BYTES = 256 * 1024
CHUNK_PERIOD_S = 30.0
#: A corrupted record length must not make the reader allocate gigabytes.
RECORD_SIZE_LIMIT_BYTES = 256 * 1024 * 1024


@dataclass(frozen=True)
class RideMetadata:
    """Where a ride log comes from (the `itt_ride` metadata record)."""

    source: str = ""
    sha256: str = ""
    device: str = ""
    rider: str = ""

    def as_record(self) -> dict[str, str]:
        """The metadata record's string map."""
        return {k: str(v) for k, v in asdict(self).items()}


class RawRecord(NamedTuple):
    """One message as stored: its channel's topic and schema, log time and CDR bytes.

    `offered_qos_profiles` is the channel's rosbag2 QoS YAML; empty means "the interface's
    QoS for a known topic, none otherwise".
    """

    topic: str
    msgtype: str
    schema_encoding: str
    schema_data: bytes
    message_encoding: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    offered_qos_profiles: str = ""


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
        self._topics = topics.topics_by_name(namespace)
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
            self._writer.finish()
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
        """Write a GPS fix, wheel speed or power reading on its input topic."""
        topic, msg = sample_to_msg(sample)
        self.write_msg(topic, msg)

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
            self._writer.flush()  # ends the chunk in progress and flushes the file
            self._chunk_start_ns = log_time_ns
        self._writer.add_message(channel_id, log_time=log_time_ns, data=data,
                                 publish_time=publish_time_ns,
                                 sequence=self._sequence[channel_id])
        self._sequence[channel_id] += 1
        self.counts[topic] += 1


class RideLogReader:
    """Stream a ride log; collects what is wrong instead of stopping at the first problem.

    After iterating, `errors` lists damage (truncation, corrupted chunks, undecodable
    messages, known topics of the wrong type) and `warnings` the benign oddities
    (unknown topics, a cut-off summary section); `skipped` counts the messages of
    unknown topics. `metadata` holds the file's metadata records.

    Args:
        path: the `.mcap` file.
        namespace: ROS namespace of the pacing topics in this log.
    """

    def __init__(self, path: str | Path, *, namespace: str = DEFAULT_NAMESPACE) -> None:
        self.path = Path(path)
        self.topics = topics.topics_by_name(namespace)
        self.errors: list[str] = []
        self.warnings: list[str] = []
        self.skipped: Counter[str] = Counter()
        self.metadata: dict[str, dict[str, str]] = {}
        self.messages_read = 0

    def records(self) -> Iterator[RawRecord]:
        """Every readable message in file order, undecoded; damage goes to `errors`.

        Raises:
            RideLogError: the file is missing or is not an MCAP file at all.
        """
        try:
            file = self.path.open("rb")
        except OSError as err:
            raise RideLogError(f"{self.path}: cannot open the ride log ({err})") from None
        with file:
            # A channel is defined once, in the chunk of its first message: take the
            # definitions from the summary too, so a corrupted first chunk does not
            # orphan the messages of every later chunk.
            schemas, channels = _summary_channels(file)
            orphans: Counter[int] = Counter()
            try:
                for rec in self._stream(file):
                    if isinstance(rec, Schema):
                        schemas[rec.id] = rec
                    elif isinstance(rec, Channel):
                        channels[rec.id] = rec
                    elif isinstance(rec, Metadata):
                        self.metadata[rec.name] = dict(rec.metadata)
                    elif isinstance(rec, Message):
                        channel = channels.get(rec.channel_id)
                        if channel is None:
                            orphans[rec.channel_id] += 1
                            continue
                        self.messages_read += 1
                        yield _raw(rec, channel, schemas.get(channel.schema_id))
            finally:
                if orphans:
                    self.errors.append(f"{orphans.total()} messages on channel ids "
                                       f"{sorted(orphans)} whose definition was lost")

    def _stream(self, file: IO[bytes]) -> Iterator[Any]:
        """The records of the data section, chunks broken up; stops at unreadable bytes."""
        file.seek(0)
        records = StreamReader(file, emit_chunks=True,
                               record_size_limit=RECORD_SIZE_LIMIT_BYTES).records
        data_ended = False
        while True:
            offset = file.tell()
            try:
                record = next(records)
            except StopIteration:
                return
            except InvalidMagic:
                if offset == 0:
                    raise RideLogError(f"{self.path}: not an MCAP file (bad magic)") from None
                self._damage(data_ended, f"bad closing magic at byte {offset}")
                return
            except Exception as err:  # noqa: BLE001  (garbage bytes raise many types)
                self._damage(data_ended, f"the record at byte {offset} is cut off or "
                                         f"unreadable ({_describe(err)})")
                return
            if isinstance(record, DataEnd):
                data_ended = True
            if not isinstance(record, Chunk):
                yield record
                continue
            try:
                yield from breakup_chunk(record, validate_crc=True)
            except Exception as err:  # noqa: BLE001  (decompression, CRC and parse errors)
                self.errors.append(
                    f"corrupted chunk at byte {offset}: messages logged "
                    f"{record.message_start_time * 1e-9:.3f} to "
                    f"{record.message_end_time * 1e-9:.3f} s are lost ({_describe(err)})")

    def _damage(self, data_ended: bool, what: str) -> None:
        if data_ended:  # every message was already read; only indexes/statistics are gone
            self.warnings.append(f"summary section damaged: {what}")
        else:
            self.errors.append(f"truncated or damaged: {what} after "
                               f"{self.messages_read} messages")

    def decoded(self) -> Iterator[tuple[RawRecord, object | None]]:
        """Every readable message with its decoded value, then raise if anything was wrong.

        The value is the core object (`GpsFix`, `WheelSpeed`, `PowerReading`, `Advice`,
        a list of `Diagnostic`) or the ROS message for types without a core twin; None for
        messages of unknown topics (skipped, counted, one warning each) and for messages
        that could not be decoded (an error each).

        Raises:
            RideLogError: after the last readable message, naming the file and listing
                every problem, when the log is damaged or a topic has the wrong type.
        """
        bad_topics: set[str] = set()
        for raw in self.records():
            yield raw, self._decode(raw, bad_topics)
        for topic, count in sorted(self.skipped.items()):
            self.warnings.append(f"skipped {count} messages of unknown topic {topic}")
        for warning in self.warnings:
            log.warning("%s: %s", self.path, warning)
        if self.errors:
            raise RideLogError(f"{self.path}: " + "; ".join(self.errors))

    def _decode(self, raw: RawRecord, bad_topics: set[str]) -> object | None:
        topic = self.topics.get(raw.topic)
        if topic is None:
            self.skipped[raw.topic] += 1
            return None
        if raw.msgtype != topic.msgtype or raw.message_encoding != MESSAGE_ENCODING:
            if raw.topic not in bad_topics:
                bad_topics.add(raw.topic)
                self.errors.append(
                    f"topic {raw.topic} has type {raw.msgtype or '?'} "
                    f"({raw.message_encoding}), expected {topic.msgtype} (cdr)")
            return None
        try:
            return msg_to_core(typestore.deserialize_cdr(raw.data, raw.msgtype))
        except Exception as err:  # noqa: BLE001  (a corrupt payload raises many types)
            self.errors.append(f"undecodable {raw.msgtype} on {raw.topic} at "
                               f"{raw.log_time_ns * 1e-9:.3f} s ({_describe(err)})")
            return None

    def __iter__(self) -> Iterator[tuple[str, float, object]]:
        """(topic, log time in s, value) of every message of a known topic.

        Raises:
            RideLogError: as `decoded`.
        """
        for raw, value in self.decoded():
            if value is not None:
                yield raw.topic, raw.log_time_ns / 1e9, value


def read_ride_log(path: str | Path, *,
                  namespace: str = DEFAULT_NAMESPACE) -> Iterator[tuple[str, float, object]]:
    """(topic, stamp in s, core object or ROS message) of each message, in log order.

    Raises:
        RideLogError: after everything readable was yielded, when the log is damaged or
            a known topic has the wrong type (names the file and the topic).
    """
    return iter(RideLogReader(path, namespace=namespace))


def message_count(path: str | Path) -> int | None:
    """The message count from the log's statistics; None when it has no readable summary."""
    try:
        with Path(path).open("rb") as file:
            summary = make_reader(file).get_summary()
    except Exception:  # noqa: BLE001  (missing or cut-off summary: the count is unknown)
        return None
    if summary is None or summary.statistics is None:
        return None
    return int(summary.statistics.message_count)


def _summary_channels(file: IO[bytes]) -> tuple[dict[int, Schema], dict[int, Channel]]:
    """Schemas and channels from the summary section; empty if it is missing or damaged."""
    try:
        summary = make_reader(file).get_summary()
    except Exception:  # noqa: BLE001  (a cut-off file has no readable summary: stream instead)
        return {}, {}
    if summary is None:
        return {}, {}
    return dict(summary.schemas), dict(summary.channels)


def _raw(msg: Message, channel: Channel, schema: Schema | None) -> RawRecord:
    return RawRecord(
        topic=channel.topic, msgtype=schema.name if schema else "",
        schema_encoding=schema.encoding if schema else "",
        schema_data=bytes(schema.data) if schema else b"",
        message_encoding=channel.message_encoding, log_time_ns=msg.log_time,
        publish_time_ns=msg.publish_time, data=bytes(msg.data),
        offered_qos_profiles=channel.metadata.get(OFFERED_QOS_KEY, ""))


def _describe(err: BaseException) -> str:
    text = str(err)
    return f"{type(err).__name__}: {text}" if text else type(err).__name__
