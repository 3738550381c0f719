"""MCAP ride logs: the format of the pacing topics as a ROS 2 bag (`cdr` + `ros2msg`), and
reading them back (writing: `ridelog_writer`).

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
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import IO, Any, NamedTuple

from mcap.exceptions import InvalidMagic
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from itt_msgs_py import DEFAULT_NAMESPACE, registry, typestore
from itt_msgs_py.qos import OFFERED_QOS_KEY
from itt_planner.errors import RideLogError

log = logging.getLogger(__name__)

#: The MCAP metadata record a ride session (node or replay) writes about itself.
SESSION_METADATA = "itt_replay"
#: The MCAP metadata record of where the ride comes from (`RideMetadata`).
METADATA_NAME = "itt_ride"
PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
#: A corrupted record length must not make the reader allocate gigabytes.
RECORD_SIZE_LIMIT_BYTES = 256 * 1024 * 1024


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


class RideLogReader:
    """Stream a ride log; collects what is wrong instead of stopping at the first problem.

    After iterating, `errors` lists damage (truncation, corrupted chunks, undecodable
    messages, known topics of the wrong type) and `warnings` the benign oddities
    (unknown topics, a cut-off summary section); `skipped` counts the messages of
    unknown topics. `metadata` holds the file's metadata records.

    Args:
        path: the `.mcap` file.
        namespace: ROS namespace of the pacing topics in this log.
        remap: a topic of the log read as a pacing topic (`{"/fix": "/itt/gps/fix"}`,
            `ros2 bag play --remap`): logs recorded from other drivers' topics.
    """

    def __init__(self, path: str | Path, *, namespace: str = DEFAULT_NAMESPACE,
                 remap: Mapping[str, str] | None = None) -> None:
        self.path = Path(path)
        self.topics = registry.topics_by_name(namespace)
        self.remap = dict(remap or {})
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
        topic = self.topics.get(self.remap.get(raw.topic, raw.topic))
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
            return registry.to_core(topic, typestore.deserialize_cdr(raw.data, raw.msgtype))
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
