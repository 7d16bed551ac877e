"""Typed messaging on top of any `Bus`: encode on the way out, validate on the way in.

Bad input never kills the caller: an undecodable sample is handed to the `ErrorSink`
(which logs, counts and reports it) and skipped; a bad request is answered with an
`ErrorReply` naming what was wrong; a message loop handles each valid message inside
`dropping`, so one whose handling fails is reported and dropped, and the loop goes on.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import NamedTuple, Protocol, TypeVar

from cbdi import keys
from cbdi.bus.base import Bus, Subscription
from cbdi.errors import CbdiError, RejectedInputError, RequestFailedError, WireError
from cbdi.wire.base import Message, decode, decode_any, encode, schema_of, sender_of
from cbdi.wire.common import ErrorReply

__all__ = [
    "ErrorSink",
    "LogSink",
    "Stamped",
    "dropping",
    "inputs",
    "messages",
    "publish",
    "request",
    "sequenced_inputs",
    "serve",
]

M = TypeVar("M", bound=Message)
R = TypeVar("R", bound=Message)


class ErrorSink(Protocol):
    """Where bad input goes: the service runtime logs it, counts it and reports it."""

    def bad_input(self, key: str, error: CbdiError) -> None: ...

    def crashed(self, key: str, error: Exception) -> None: ...


class LogSink:
    """An `ErrorSink` that only remembers what it got (tests, small tools)."""

    def __init__(self) -> None:
        self.errors: list[tuple[str, Exception]] = []

    def bad_input(self, key: str, error: CbdiError) -> None:
        self.errors.append((key, error))

    def crashed(self, key: str, error: Exception) -> None:
        self.errors.append((key, error))


@contextmanager
def dropping(sink: ErrorSink, key: str, message: Message) -> Iterator[None]:
    """Handle one input inside this: if handling fails, report it and drop the message.

    A domain error (`CbdiError`, or `ValueError` from the pure core refusing a value)
    is bad input, named by schema, sender and key; anything else is a handler bug,
    logged with its trace as a crash. Either way the message loop goes on: a service
    never dies of what it was sent.
    """
    try:
        yield
    except (CbdiError, ValueError) as exc:
        reason = str(exc) or type(exc).__name__
        code = str(getattr(exc, "code", "rejected"))
        schema, sender = schema_of(type(message)), sender_of(message)
        sink.bad_input(key, RejectedInputError(schema, reason, key, sender, code))
    except Exception as exc:
        sink.crashed(key, exc)


async def publish(bus: Bus, key: str, message: Message, *, block: bool = False) -> None:
    """Encode and publish `message` on `key`."""
    await bus.publish(key, encode(message), block=block)


def messages(
    bus: Bus, key_expr: str, cls: type[M], sink: ErrorSink
) -> AsyncIterator[tuple[str, M]]:
    """Yield `(key, message)` for every valid `cls` sample on `key_expr`; skip bad ones.

    The subscription is declared now, not at the first iteration, so a service that
    declares liveliness after this call is guaranteed to receive what follows.
    """
    return _decoded(bus.subscribe(key_expr), cls, sink)


async def _decoded(
    sub: Subscription, cls: type[M], sink: ErrorSink
) -> AsyncIterator[tuple[str, M]]:
    try:
        async for sample in sub:
            try:
                message = decode(sample.payload, cls, sample.key)
            except WireError as exc:
                sink.bad_input(sample.key, exc)
                continue
            yield sample.key, message
    finally:
        await sub.close()


def inputs(
    bus: Bus, key_exprs: Sequence[str], classes: tuple[type[Message], ...], sink: ErrorSink
) -> AsyncIterator[tuple[str, Message]]:
    """Yield `(key, message)` from several keys in arrival order, each one of `classes`.

    For a service with several inputs that must be handled one at a time, in order. The
    subscriptions exist from this call on; undecodable samples go to `sink`.
    """
    return _decoded_any(bus.subscribe(key_exprs), classes, sink)


class Stamped(NamedTuple):
    """A decoded input with its sender's stamp: `seq` on its key, `order` over all keys."""

    key: str
    seq: int
    order: int
    message: Message


def sequenced_inputs(
    bus: Bus, key_exprs: Sequence[str], classes: tuple[type[Message], ...], sink: ErrorSink
) -> AsyncIterator[Stamped]:
    """Like `inputs`, with each sample's stamp (`Stamped`).

    Lockstep gates use it to tell which messages an acknowledgement covers, and in which
    order their sender sent them.
    """
    return _sequenced_any(bus.subscribe(key_exprs), classes, sink)


async def _sequenced_any(
    sub: Subscription, classes: tuple[type[Message], ...], sink: ErrorSink
) -> AsyncIterator[Stamped]:
    try:
        async for sample in sub:
            try:
                message = decode_any(sample.payload, classes, sample.key)
            except WireError as exc:
                sink.bad_input(sample.key, exc)
                continue
            yield Stamped(sample.key, sample.seq, sample.order, message)
    finally:
        await sub.close()


async def _decoded_any(
    sub: Subscription, classes: tuple[type[Message], ...], sink: ErrorSink
) -> AsyncIterator[tuple[str, Message]]:
    try:
        async for sample in sub:
            try:
                message = decode_any(sample.payload, classes, sample.key)
            except WireError as exc:
                sink.bad_input(sample.key, exc)
                continue
            yield sample.key, message
    finally:
        await sub.close()


async def request(
    bus: Bus, key: str, message: Message, reply_cls: type[R], *, timeout: float = 2.0
) -> R:
    """Send a typed request; return the typed reply or raise RequestFailedError."""
    payload = await bus.request(key, encode(message), timeout=timeout)
    reply = decode_any(payload, (reply_cls, ErrorReply), key)
    if isinstance(reply, ErrorReply):
        raise RequestFailedError(key, reply.code, reply.message)
    return reply  # type: ignore[return-value]


async def serve(
    bus: Bus,
    key_expr: str,
    request_cls: type[M],
    handler: Callable[[str, M], Awaitable[Message]],
    sink: ErrorSink,
    *,
    trace: bool = True,
    trace_as: str = "",
) -> None:
    """Answer typed requests on `key_expr` until cancelled.

    With `trace`, each request and its reply are mirrored on `cbdi/trace/...` so that a
    recorder subscribed to `cbdi/**` sees RPC traffic too (Zenoh does not show queries to
    subscribers): under the key asked on, or under `trace_as` for an endpoint scoped by
    a last chunk (`cbdi/world/rpc/act/<agent>`: its requests name the agent anyway).
    """

    async def answer(key: str, payload: bytes) -> bytes:
        if trace:
            await bus.publish(keys.trace_request(trace_as or key), payload)
        reply = await _reply_to(key, payload, request_cls, handler, sink)
        encoded = encode(reply)
        if trace:
            await bus.publish(keys.trace_reply(trace_as or key), encoded)
        return encoded

    await bus.serve(key_expr, answer)


async def _reply_to(
    key: str,
    payload: bytes,
    request_cls: type[M],
    handler: Callable[[str, M], Awaitable[Message]],
    sink: ErrorSink,
) -> Message:
    try:
        req = decode(payload, request_cls, key)
    except WireError as exc:
        sink.bad_input(key, exc)
        return ErrorReply(code="bad_message", message=str(exc))
    try:
        return await handler(key, req)
    except CbdiError as exc:
        sink.bad_input(key, exc)
        return ErrorReply(code=getattr(exc, "code", "error"), message=str(exc))
    except Exception as exc:  # a handler bug must not take the service down
        sink.crashed(key, exc)
        return ErrorReply(code="internal", message=f"{type(exc).__name__}: {exc}")
