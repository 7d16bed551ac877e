"""Write cbdi traffic to MCAP: one channel per key, msgpack payloads, sender stamps.

Each channel's metadata names the agent, the component, the stream and the schema of
its messages; the schema record carries the message's JSON Schema. Files are chunked and
zstd-compressed, and rotate by size or duration when asked (`run.mcap`, `run-001.mcap`,
...). `close()` finishes a file (summary and footer); `flush()`, which the service calls
twice a second, writes what was recorded so far, so a recorder killed outright loses at
most the last half second: readers take a file with no footer up to its last record.

A new recording replaces the file and its parts of an earlier one; a recorder restarted
within the run (`resume`) never overwrites: it goes on in the next free part, and the
readers (`cbdi_monitor.reader`) read a recording's parts in order as one.

Traffic that is no cbdi message (garbage a client sent, mirrored on the trace keys) is
recorded only in part, so a flood of it cannot grow the file without limit: the first
GARBAGE_PER_KEY samples per key and GARBAGE_TOTAL in all; the rest is counted in
`dropped`, per key, and not written.
"""

from __future__ import annotations

import glob
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from mcap.writer import CompressionType, Writer

from cbdi import keys
from cbdi_monitor.schemas import json_schema, peek_schema, wire_classes

__all__ = ["ENCODING", "McapRecorder", "Rotation", "part_path", "part_paths"]

ENCODING = "msgpack"
GARBAGE_PER_KEY = 10  # samples without a known schema recorded per key
GARBAGE_TOTAL = 1000  # and in all


def part_path(base: Path, index: int) -> Path:
    """The file of part `index` of the recording `base` (0: `base` itself)."""
    return base if index == 0 else base.with_name(f"{base.stem}-{index:03d}{base.suffix}")


def part_paths(base: Path) -> list[Path]:
    """The recording `base` and its parts that exist, in order (`base` first, even when
    it does not exist, so that reading it says so)."""
    parts = sorted(base.parent.glob(f"{glob.escape(base.stem)}-[0-9][0-9][0-9]{base.suffix}"))
    return [base, *parts]


@dataclass(frozen=True)
class Rotation:
    """Start a new file after `max_bytes` or `max_seconds` (0: never)."""

    max_bytes: int = 0
    max_seconds: float = 0.0


class McapRecorder:
    """An open recording (one or more files when rotating)."""

    def __init__(
        self,
        path: str | Path,
        rotation: Rotation | None = None,
        chunk_size: int = 256 * 1024,
        profile: str = "cbdi",
        resume: bool = False,
    ) -> None:
        self.base = Path(path)
        self.resume = resume  # a restart within the run: go on in the next free part
        self.rotation = rotation or Rotation()
        self.chunk_size = chunk_size
        self.profile = profile
        self.files: list[Path] = []
        self.counts: dict[str, int] = {}
        self._stream: BinaryIO | None = None
        self._writer: Writer | None = None
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._opened_ns = 0
        self.closed = False
        self.late = 0  # messages that arrived after close (not written)
        self.garbage: dict[str, int] = {}  # samples without a known schema, recorded
        self._garbage_total = 0
        self.dropped: dict[str, int] = {}  # and beyond the limits, not recorded

    def _open(self, log_ns: int) -> Writer:
        if not self.files and not self.resume:
            for old in part_paths(self.base)[1:]:  # an earlier recording's parts
                old.unlink(missing_ok=True)
        index = len(self.files)
        path = part_path(self.base, index)
        while self.resume and path.exists():
            index += 1
            path = part_path(self.base, index)
        path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = path.open("wb")
        writer = Writer(self._stream, chunk_size=self.chunk_size, compression=CompressionType.ZSTD)
        writer.start(profile=self.profile, library="cbdi-monitor")
        self.files.append(path)
        self._writer, self._channels, self._schemas = writer, {}, {}
        self._opened_ns = log_ns
        return writer

    def _due_for_rotation(self, log_ns: int) -> bool:
        r = self.rotation
        if self._stream is None:
            return False
        too_big = r.max_bytes > 0 and self._stream.tell() >= r.max_bytes
        too_old = r.max_seconds > 0 and log_ns - self._opened_ns >= r.max_seconds * 1e9
        return too_big or too_old

    def _channel(self, writer: Writer, key: str, payload: bytes) -> int:
        schema_name = peek_schema(payload)
        schema_id = self._schemas.get(schema_name, 0)
        if schema_name and schema_name not in self._schemas:
            data = json_schema(schema_name)
            schema_id = (
                writer.register_schema(name=schema_name, encoding="jsonschema", data=data)
                if data
                else 0
            )
            self._schemas[schema_name] = schema_id
        metadata = {**keys.describe(key), "schema": schema_name}
        channel = writer.register_channel(
            topic=key, message_encoding=ENCODING, schema_id=schema_id, metadata=metadata
        )
        self._channels[key] = channel
        return channel

    def write(
        self, key: str, payload: bytes, log_ns: int, publish_ns: int = 0, seq: int = 0
    ) -> bool:
        """Append one message; `log_ns` is the recorder's receive time. Return whether
        it was written (not: after close, or garbage beyond the limits)."""
        if self.closed:
            self.late += 1
            return False
        if peek_schema(payload) not in wire_classes() and not self._keep_garbage(key):
            self.dropped[key] = self.dropped.get(key, 0) + 1
            return False
        writer = self._writer
        if writer is None or self._due_for_rotation(log_ns):
            self.finish_file()
            writer = self._open(log_ns)
        channel = self._channels.get(key)
        if channel is None:
            channel = self._channel(writer, key, payload)
        writer.add_message(
            channel_id=channel,
            log_time=log_ns,
            data=payload,
            publish_time=publish_ns or log_ns,
            sequence=seq & 0xFFFFFFFF,
        )
        self.counts[key] = self.counts.get(key, 0) + 1
        return True

    def _keep_garbage(self, key: str) -> bool:
        """Whether to record one more sample without a known schema on `key`."""
        here = self.garbage.get(key, 0)
        if here >= GARBAGE_PER_KEY or self._garbage_total >= GARBAGE_TOTAL:
            return False
        self.garbage[key] = here + 1
        self._garbage_total += 1
        return True

    def flush(self) -> None:
        """Write what was recorded so far (the chunk in progress) to the file."""
        if self._writer is not None:
            self._writer.flush()  # type: ignore[no-untyped-call]

    def finish_file(self) -> None:
        """Finish the current file (summary, index, footer) so it is readable."""
        if self._writer is not None:
            self._writer.finish()  # type: ignore[no-untyped-call]
            self._writer = None
        if self._stream is not None:
            self._stream.close()
            self._stream = None

    def close(self) -> None:
        """Finish the recording; nothing is written after this."""
        self.finish_file()
        self.closed = True
