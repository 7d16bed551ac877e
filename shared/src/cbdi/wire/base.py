"""Base of every wire type: frozen msgspec structs tagged with schema name and version.

A message on the wire is a msgpack map whose `schema` field is `<name>/<version>`, e.g.
`cbdi.world.ActionRequest/1`. Decoding validates field types and presence against the
expected class and rejects anything else with a `WireError`; unknown extra fields are
tolerated so that newer senders can talk to older receivers.
"""

from __future__ import annotations

import sys
from typing import Any, TypeVar

import msgspec

from cbdi.errors import WireError

__all__ = ["Message", "decode", "decode_any", "encode", "schema_of", "sender_of"]

M = TypeVar("M", bound="Message")


class Message(
    msgspec.Struct,
    frozen=True,
    kw_only=True,
    tag_field="schema",
    forbid_unknown_fields=False,
):
    """Base class of wire messages; subclasses set `tag="cbdi.<area>.<Name>/<version>"`."""


_encoder = msgspec.msgpack.Encoder()
_decoders: dict[type[Any], msgspec.msgpack.Decoder[Any]] = {}


def schema_of(cls: type[Message]) -> str:
    """Return the schema name with version (`cbdi.world.Tick/1`) of a message class."""
    tag = msgspec.inspect.type_info(cls).tag  # type: ignore[attr-defined]
    return str(tag)


def sender_of(message: object) -> str:
    """Return who sent `message` by its own word (`agent` or `from_agent`), or ""."""
    for name in ("from_agent", "agent"):
        value = getattr(message, name, None)
        if isinstance(value, str) and value:
            return value[:64]
    return ""


class _Sender(msgspec.Struct):
    """The sender fields of any message, read leniently to name who sent a bad one."""

    agent: Any = None
    from_agent: Any = None


_sender_decoder = msgspec.msgpack.Decoder(_Sender)


def _peek(payload: bytes) -> str:
    try:
        return sender_of(_sender_decoder.decode(payload))
    except msgspec.DecodeError:
        return ""


def encode(message: Message) -> bytes:
    """Encode a message as msgpack bytes."""
    return _encoder.encode(message)


def decode(payload: bytes, cls: type[M], key: str | None = None) -> M:
    """Decode `payload` as a `cls` message or raise `WireError` saying what is wrong."""
    decoder = _decoders.get(cls)
    if decoder is None:
        decoder = msgspec.msgpack.Decoder(cls)
        _decoders[cls] = decoder
    try:
        return decoder.decode(payload)  # type: ignore[no-any-return]
    except msgspec.DecodeError as exc:
        raise WireError(schema_of(cls), _explain(exc, payload), key, _peek(payload)) from None


def decode_any(
    payload: bytes, classes: tuple[type[Message], ...], key: str | None = None
) -> Message:
    """Decode `payload` as one of several message classes, chosen by its `schema` tag."""
    union_key = classes
    decoder = _union_decoders.get(union_key)
    if decoder is None:
        decoder = msgspec.msgpack.Decoder(_union(classes))
        _union_decoders[union_key] = decoder
    try:
        return decoder.decode(payload)  # type: ignore[no-any-return]
    except msgspec.DecodeError as exc:
        names = " | ".join(schema_of(c) for c in classes)
        raise WireError(names, _explain(exc, payload), key, _peek(payload)) from None


_union_decoders: dict[tuple[type[Message], ...], msgspec.msgpack.Decoder[Any]] = {}


def _union(classes: tuple[type[Message], ...]) -> Any:
    result: Any = classes[0]
    for cls in classes[1:]:
        result = result | cls
    return result


def _explain(exc: msgspec.DecodeError, payload: bytes) -> str:
    """Turn msgspec's message into one a user can act on (what, where)."""
    text = str(exc)
    if text.startswith("Expected `object`, got") and "$" not in text:
        return f"not a message map ({text[len('Expected `object`, ') :]}); {len(payload)} bytes"
    if "MessagePack data is malformed" in text or "truncated" in text:
        return f"garbage bytes, not msgpack ({len(payload)} bytes)"
    if "at `$.schema`" in text:
        return f"wrong schema ({text})"
    for bound in (_LOW, _HIGH):  # the bounds of `Finite`: NaN and infinities fail them
        if bound in text:
            return "expected a finite number" + text[text.index(bound) + len(bound) :]
    return text


_HIGH = f"Expected `float` <= {sys.float_info.max!r}"
_LOW = f"Expected `float` >= {-sys.float_info.max!r}"
