"""Every wire type by schema name, and its JSON Schema (for MCAP schema records)."""

from __future__ import annotations

import json
from functools import cache

import msgspec

import cbdi.wire.agent
import cbdi.wire.common
import cbdi.wire.planner
import cbdi.wire.world
from cbdi.plugins import percept_types
from cbdi.wire.base import Message, schema_of

__all__ = ["json_schema", "peek_schema", "wire_classes"]


class _Peek(msgspec.Struct):
    schema: str = ""


_peek = msgspec.msgpack.Decoder(_Peek)


def peek_schema(payload: bytes) -> str:
    """Return the `schema` field of a msgpack message, or "" if it has none."""
    try:
        return _peek.decode(payload).schema
    except (msgspec.DecodeError, TypeError):
        return ""


@cache
def wire_classes() -> dict[str, type[Message]]:
    """Return every known message class by its schema name: the core's and the
    installed domains' (their percepts, `cbdi.plugins.percept_types`, are imported
    here); a base class without a versioned schema (`Percept`) is none."""
    percept_types()
    found: dict[str, type[Message]] = {}
    todo = list(Message.__subclasses__())
    while todo:
        cls = todo.pop()
        todo.extend(cls.__subclasses__())
        if "/" in schema_of(cls):
            found[schema_of(cls)] = cls
    return found


@cache
def json_schema(name: str) -> bytes:
    """Return the JSON Schema of message `name` (b"" if unknown)."""
    cls = wire_classes().get(name)
    if cls is None:
        return b""
    return json.dumps(msgspec.json.schema(cls)).encode()


# Imported for their side effect: every message class is then a known subclass.
_MODULES = (cbdi.wire.agent, cbdi.wire.common, cbdi.wire.planner, cbdi.wire.world)
