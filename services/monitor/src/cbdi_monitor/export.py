"""`cbdi export run.mcap --json out.mcap`: the same recording in JSON encoding.

Foxglove does not decode msgpack; the JSON copy keeps every channel, its metadata
(`agent`, `component`, `stream`, `schema`), each message's times and sequence, and the
JSON Schema of each message type. A source that does not read leaves no copy behind.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import msgpack
from mcap.writer import CompressionType, Writer

from cbdi.errors import CbdiError
from cbdi_monitor.reader import read_messages
from cbdi_monitor.schemas import json_schema

__all__ = ["export_json", "main"]


def _to_json(payload: bytes) -> bytes:
    try:
        value = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except (msgpack.ExtraData, msgpack.FormatError, msgpack.StackError, ValueError):
        value = {"undecodable": payload.hex()}
    return json.dumps(value, default=repr, separators=(",", ":")).encode()


def export_json(source: str | Path, target: str | Path) -> int:
    """Write `target` with every message of `source` as JSON; return the message count."""
    try:
        return _export(source, Path(target))
    except CbdiError:
        Path(target).unlink(missing_ok=True)  # half a copy would pass for a whole one
        raise


def _export(source: str | Path, target: Path) -> int:
    count = 0
    try:
        out = target.open("wb")
    except OSError as exc:
        raise CbdiError(f"{target}: cannot write ({exc.strerror or exc})") from None
    with out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start(profile="cbdi", library="cbdi-monitor export")
        channels: dict[str, int] = {}
        schemas: dict[str, int] = {}
        for m in read_messages(source):
            if m.key not in channels:
                schema_id = schemas.get(m.schema, 0)
                data = json_schema(m.schema) if m.schema else b""
                if data and m.schema not in schemas:
                    schema_id = writer.register_schema(m.schema, "jsonschema", data)
                    schemas[m.schema] = schema_id
                metadata = {**m.metadata, "schema": m.schema}
                channels[m.key] = writer.register_channel(m.key, "json", schema_id, metadata)
            writer.add_message(channels[m.key], m.log_ns, _to_json(m.payload), m.publish_ns, m.seq)
            count += 1
        writer.finish()  # type: ignore[no-untyped-call]
    return count


def main(argv: Sequence[str] | None = None) -> int:
    """Run `cbdi export FILE --json OUT`."""
    parser = argparse.ArgumentParser(prog="cbdi export", description=__doc__)
    parser.add_argument("file", help="an MCAP recording (msgpack)")
    parser.add_argument("--json", metavar="OUT", required=True, help="write a JSON-encoded copy")
    args = parser.parse_args(list(argv) if argv is not None else None)
    try:
        count = export_json(args.file, args.json)
    except CbdiError as exc:
        print(f"cbdi export: {exc}", file=sys.stderr)
        return 2
    print(f"exported {count} messages to {args.json}", file=sys.stderr)
    return 0
