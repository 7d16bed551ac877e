"""Read a cbdi MCAP recording back, message by message, in log-time order."""

from __future__ import annotations

import struct
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader

from cbdi_monitor.errors import RecordingError

__all__ = ["RecordedMessage", "RecordingError", "read_messages"]


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
    """Yield the messages of `path` (only of `keys` topics, if given) in log-time order."""
    p = Path(path)
    try:
        stream = p.open("rb")
    except OSError as exc:
        raise RecordingError(f"{p}: {exc.strerror or exc}") from None
    with stream:
        try:
            reader = make_reader(stream)
            for _schema, channel, message in reader.iter_messages(topics=keys):
                yield RecordedMessage(
                    key=channel.topic,
                    payload=message.data,
                    log_ns=message.log_time,
                    publish_ns=message.publish_time,
                    seq=message.sequence,
                    schema=channel.metadata.get("schema", ""),
                    encoding=channel.message_encoding,
                    metadata=channel.metadata,
                )
        except (McapError, EOFError, ValueError, struct.error) as exc:  # struct: too short
            raise RecordingError(f"{p}: not a readable MCAP file ({exc})") from None
        except Exception as exc:  # a damaged file fails deep in mcap or zstandard: seek, chunk
            why = f"{type(exc).__name__}: {exc}"
            raise RecordingError(f"{p}: not a readable MCAP file ({why})") from None
