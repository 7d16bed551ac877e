"""Typed, versioned wire messages (msgpack via msgspec) shared by all cbdi services."""

from cbdi.wire.base import Message, decode, decode_any, encode, schema_of

__all__ = ["Message", "decode", "decode_any", "encode", "schema_of"]
