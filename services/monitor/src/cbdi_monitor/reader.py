"""Read a cbdi MCAP recording back, message by message, in log-time order."""

from __future__ import annotations

import struct
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap.records import Channel, Message

from cbdi_monitor.errors import RecordingError
from cbdi_monitor.recorder import part_paths

__all__ = ["RecordedMessage", "RecordingError", "read_messages"]

MCAP0_MAGIC = b"\x89MCAP0\r\n"  # what an MCAP file starts and, once finished, ends with


@dataclass(frozen=True, slots=True)
class RecordedMessage:
    """One recorded message with its channel's key, schema name, encoding and metadata."""

    key: str
    payload: bytes
    log_ns: int
    publish_ns: int
    seq: int
    schema: str
    encoding: str
    metadata: Mapping[str, str] = field(default_factory=dict)  # agent, component, stream


def read_messages(path: str | Path, keys: list[str] | None = None) -> Iterator[RecordedMessage]:
    """Yield the messages of the recording `path` (only of `keys` topics, if given) in
    log-time order: the file, then its parts (`run-001.mcap`, ...: rotated, or written by
    a recorder restarted within the run) in order. A file with no footer (its recorder
    was killed) is read up to its last whole record; an empty part is skipped."""
    base = Path(path)
    for part in part_paths(base):
        if part != base and part.exists() and part.stat().st_size == 0:
            continue  # a recorder killed before it wrote anything
        yield from _read_file(part, keys)


def _read_file(p: Path, keys: list[str] | None) -> Iterator[RecordedMessage]:
    try:
        stream = p.open("rb")
    except OSError as exc:
        raise RecordingError(f"{p}: {exc.strerror or exc}") from None
    with stream:
        if _unfinished(stream):
            yield from _read_unfinished(stream, keys)
            return
        try:
            reader = make_reader(stream)
            for _schema, channel, message in reader.iter_messages(topics=keys):
                yield _recorded(channel, message)
        except (McapError, EOFError, ValueError, struct.error) as exc:  # struct: too short
            raise RecordingError(f"{p}: not a readable MCAP file ({exc})") from None
        except Exception as exc:  # a damaged file fails deep in mcap or zstandard: seek, chunk
            why = f"{type(exc).__name__}: {exc}"
            raise RecordingError(f"{p}: not a readable MCAP file ({why})") from None


def _unfinished(stream: BinaryIO) -> bool:
    """Whether the file starts as an MCAP file but has no footer (nobody finished it)."""
    head = stream.read(len(MCAP0_MAGIC))
    stream.seek(-min(len(MCAP0_MAGIC), stream.seek(0, 2)), 2)
    tail = stream.read(len(MCAP0_MAGIC))
    stream.seek(0)
    return head == MCAP0_MAGIC and tail != MCAP0_MAGIC


def _read_unfinished(stream: BinaryIO, keys: list[str] | None) -> Iterator[RecordedMessage]:
    """Read records in file order until the file ends, whole or cut short."""
    reader = NonSeekingReader(stream, validate_crcs=False)
    wanted = None if keys is None else set(keys)
    try:
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            if wanted is None or channel.topic in wanted:
                yield _recorded(channel, message)
    except Exception:  # the cut: the last record is incomplete
        return


def _recorded(channel: Channel, message: Message) -> RecordedMessage:
    return RecordedMessage(
        key=channel.topic,
        payload=message.data,
        log_ns=message.log_time,
        publish_ns=message.publish_time,
        seq=message.sequence,
        schema=channel.metadata.get("schema", ""),
        encoding=channel.message_encoding,
        metadata=channel.metadata,
    )
