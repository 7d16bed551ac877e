"""The real `Bus`: Eclipse Zenoh, as a client of a router or as a peer.

Zenoh's Python API calls back on its own threads. Every callback here does one thing:
hand the item to the asyncio loop with `call_soon_threadsafe`. The session is always
closed in `close()` (an unclosed session with callback subscribers hangs at exit).

Nothing published is lost while the router restarts: publications go out through
Zenoh's advanced publishers (numbered, with a cache of the last `CACHE_SAMPLES` per
key), and subscriptions are advanced subscribers that ask each publisher they heard
from, every `RECOVERY_PERIOD` (2 s), for what came after its last sample they have, and
fetch what is missing from its cache once the network is back, in order. A subscription with
`history` (a recorder's) also gets what every publisher still holds in its cache when
it joins, so a restarted recorder gets what was sent while it was down. Heartbeats
(wall-clock, many) are plain publications.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime
import json
import struct
import time
from collections import Counter, OrderedDict, deque
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import zenoh
import zenoh.ext
from zenoh.handlers import Callback

from cbdi.bus.base import AliveEvent, Handler, Sample
from cbdi.errors import BusClosedError, ConfigError, RequestFailedError, RequestTimeoutError
from cbdi.keys import is_heartbeat

__all__ = ["BusConfig", "ZenohBus", "open_bus", "zenoh_config"]

T = TypeVar("T")
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
_MAX_PUBLISHERS = 1024
CACHE_SAMPLES = 256  # per key: what a subscriber can recover after an outage
# Between a subscriber's "what next?" to each publisher it heard from: the queries grow
# with subscriptions times publishers (16 robots on campus-30x30: at 0.5 s they were
# most of the router's CPU, 20.7 s in 50 s, against 10.9 at 2 s), and only the last
# samples before a silence need them (a gap before a later sample is seen at once).
RECOVERY_PERIOD = datetime.timedelta(seconds=2)


@dataclass(frozen=True)
class BusConfig:
    """How a service joins the Zenoh network.

    `client` (default) connects to the router(s) in `connect` and waits up to
    `connect_timeout` seconds for one to come up; `peer` listens on `listen` and connects
    to `connect` directly, with gossip scouting so that three or more peers find each other.
    With a `user`, the session proves who it is to the router (Zenoh's user-password
    authentication; the router's access control then applies, docs/security.md).
    """

    mode: str = "client"
    connect: tuple[str, ...] = (DEFAULT_ENDPOINT,)
    listen: tuple[str, ...] = ()
    connect_timeout: float = 10.0
    extra: dict[str, Any] = field(default_factory=dict)
    user: str = ""
    password: str = field(default="", repr=False)


def zenoh_config(cfg: BusConfig) -> zenoh.Config:
    """Build the Zenoh configuration for `cfg` (multicast scouting off: explicit endpoints)."""
    if cfg.mode not in ("client", "peer", "router"):
        raise ConfigError("bus", "mode", f"expected client, peer or router, got {cfg.mode!r}")
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(cfg.mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    # No shared-memory transport: cbdi's messages are small (belief changes, plans), and
    # its pool (16 MB per session, mapped again by every session it reaches) would cost
    # each service some 20 to 64 MB of memory for nothing (`extra` turns it back on).
    conf.insert_json5("transport/shared_memory/enabled", "false")
    # Advanced publishers' caches keep timestamped samples.
    conf.insert_json5("timestamping/enabled", "true")
    if cfg.connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(cfg.connect)))
    if cfg.listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(cfg.listen)))
    timeout_ms = int(cfg.connect_timeout * 1000)
    conf.insert_json5("connect/timeout_ms", json.dumps({cfg.mode: timeout_ms}))
    if cfg.mode == "peer":
        conf.insert_json5("scouting/gossip/enabled", "true")
    if cfg.user:
        conf.insert_json5("transport/auth/usrpwd/user", json.dumps(cfg.user))
        conf.insert_json5("transport/auth/usrpwd/password", json.dumps(cfg.password))
    for key, value in cfg.extra.items():
        try:
            conf.insert_json5(key, json.dumps(value))
        except zenoh.ZError as exc:  # a setting Zenoh does not take (say, an ACL's typo)
            raise ConfigError("zenoh settings", key, str(exc).split(" at /")[0]) from None
    return conf


async def open_bus(cfg: BusConfig) -> ZenohBus:
    """Open a Zenoh session without blocking the loop (a client may wait for its router)."""
    conf = zenoh_config(cfg)
    try:
        session = await asyncio.to_thread(zenoh.open, conf)
    except zenoh.ZError as exc:
        endpoints = ", ".join(cfg.connect) or "(none)"
        who = f" as user {cfg.user!r} (refused if the router knows no such user or password)"
        why = f"cannot join Zenoh via {endpoints}{who if cfg.user else ''}: {exc}"
        raise ConfigError("bus", "connect", why) from None
    return ZenohBus(session, asyncio.get_running_loop())


_STAMP = struct.Struct("<QQQ")
_OLD_STAMP = struct.Struct("<QQ")  # before `order`: still read


def stamp(seq: int, order: int = 0) -> bytes:
    """Return the attachment every publication carries: sequence on its key, wall time
    (ns) and the sender's publication number over all keys (`order`)."""
    # Wall time on purpose: it is the sender's publish time recorded in MCAP files.
    return _STAMP.pack(seq, time.time_ns(), order)


def unstamp(attachment: Any) -> tuple[int, int, int]:
    """Read (sequence, sent_ns, order) from an attachment; zeros if absent or foreign."""
    if attachment is None:
        return 0, 0, 0
    raw = attachment.to_bytes()
    if len(raw) == _OLD_STAMP.size:
        seq, sent_ns = _OLD_STAMP.unpack(raw)
        return int(seq), int(sent_ns), 0
    if len(raw) != _STAMP.size:
        return 0, 0, 0
    seq, sent_ns, order = _STAMP.unpack(raw)
    return int(seq), int(sent_ns), int(order)


def _post(loop: asyncio.AbstractEventLoop, fn: Any, *args: Any) -> None:
    """Hand a call to the loop from a Zenoh thread; a closed loop means we are exiting."""
    try:  # noqa: SIM105  (not contextlib.suppress: this runs for every sample)
        loop.call_soon_threadsafe(fn, *args)
    except RuntimeError:
        pass


class _Inbox(Generic[T]):
    """An unbounded queue fed from Zenoh threads, read on the loop; nothing is dropped.

    `push` may be called from any thread: items gather in a deque and the loop is woken
    once per burst (one `call_soon_threadsafe` for many samples under load, which is what
    lets a recorder keep up). `get` and `get_all` run on the loop.
    """

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._incoming: deque[T] = deque()  # appended on Zenoh threads (atomic under the GIL)
        self._items: deque[T] = deque()
        self._scheduled = False
        self._waiter: asyncio.Future[None] | None = None

    def push(self, item: T) -> None:
        self._incoming.append(item)
        if not self._scheduled:
            self._scheduled = True
            _post(self._loop, self._flush)

    def put(self, item: T) -> None:
        """Add an item from the loop thread."""
        self._items.append(item)
        self._wake()

    def _flush(self) -> None:
        self._scheduled = False  # before draining: a later push schedules a new flush
        incoming, items = self._incoming, self._items
        while incoming:
            items.append(incoming.popleft())
        self._wake()

    def _wake(self) -> None:
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    async def get(self) -> T:
        while not self._items:
            self._waiter = self._loop.create_future()
            try:
                await self._waiter
            finally:
                self._waiter = None
        return self._items.popleft()


class _ZenohSubscription:
    """One inbox fed by a Zenoh subscriber per key expression, in arrival order."""

    def __init__(self, bus: ZenohBus, key_exprs: Sequence[str], history: bool) -> None:
        self.queue: _Inbox[Sample | None] = _Inbox(bus.loop)
        push = self.queue.push

        def on_sample(s: zenoh.Sample) -> None:
            seq, sent_ns, order = unstamp(s.attachment)
            push(Sample(str(s.key_expr), s.payload.to_bytes(), seq, sent_ns, order))

        self._bus = bus
        # Periodic queries, not heartbeats: a subscriber asks only the publishers it heard
        # from for what came after their last sample it has; with heartbeats a new
        # subscriber would fetch every cache (what was sent before it subscribed).
        # (the stub says float; the binding wants a timedelta)
        period: Any = RECOVERY_PERIOD
        recovery = zenoh.ext.RecoveryConfig(periodic_queries=period, heartbeat=None)
        past = zenoh.ext.HistoryConfig(detect_late_publishers=True) if history else None
        self._subs: list[Any] = [
            zenoh.ext.declare_advanced_subscriber(
                bus.session, k, Callback(on_sample), history=past, recovery=recovery
            )
            for k in key_exprs
        ]
        bus._closeables.add(self)

    def __aiter__(self) -> AsyncIterator[Sample]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[Sample]:
        while (sample := await self.queue.get()) is not None:
            yield sample

    async def close(self) -> None:
        if self._subs:
            subs, self._subs = self._subs, []
            self._bus._closeables.discard(self)
            for sub in subs:
                with contextlib.suppress(zenoh.ZError):
                    sub.undeclare()
            self.queue.put(None)


class _ZenohToken:
    def __init__(self, bus: ZenohBus, key: str) -> None:
        self._bus = bus
        self._token: Any = bus.session.liveliness().declare_token(key)
        bus._closeables.add(self)

    async def close(self) -> None:
        if self._token is not None:
            token, self._token = self._token, None
            self._bus._closeables.discard(self)
            with contextlib.suppress(zenoh.ZError):
                token.undeclare()


class ZenohBus:
    """`cbdi.bus.Bus` over an open Zenoh session."""

    def __init__(self, session: zenoh.Session, loop: asyncio.AbstractEventLoop) -> None:
        self.session = session
        self.loop = loop
        self._closeables: set[_ZenohSubscription | _ZenohToken] = set()
        self._publishers: OrderedDict[tuple[str, bool], Any] = OrderedDict()
        self.sent: Counter[str] = Counter()  # publications per key, also the sequence
        self.published = 0  # publications over all keys: the order of what we sent
        self.sending = 0  # puts under way (a blocking one waits for room: congestion)
        self._queriers: OrderedDict[tuple[str, float], Any] = OrderedDict()
        self._closed = False

    def _check(self) -> None:
        if self._closed:
            raise BusClosedError("zenoh bus is closed")

    async def publish(self, key: str, payload: bytes, *, block: bool = False) -> None:
        self._check()
        publisher = self._publishers.get((key, block))
        if publisher is None:
            publisher = self._declare_publisher(key, block)
        seq = self.sent[key] = self.sent[key] + 1
        self.published += 1
        self.sending += 1
        try:
            publisher.put(payload, attachment=stamp(seq, self.published))
        finally:
            self.sending -= 1

    def pulse(self, key: str, payload: bytes) -> None:
        if self._closed:
            return
        with contextlib.suppress(zenoh.ZError):  # closing meanwhile: a pulse is worth nothing
            self.session.put(key, payload, congestion_control=zenoh.CongestionControl.DROP)

    def _declare_querier(self, key: str, timeout: float) -> Any:
        """Declare (and cache) a querier for `key`: repeated requests skip declaration."""
        if len(self._queriers) >= _MAX_PUBLISHERS:
            _, oldest = self._queriers.popitem(last=False)
            with contextlib.suppress(zenoh.ZError):
                oldest.undeclare()
        querier = self.session.declare_querier(
            key, timeout=timeout, congestion_control=zenoh.CongestionControl.BLOCK
        )
        self._queriers[(key, timeout)] = querier
        return querier

    def _declare_publisher(self, key: str, block: bool) -> Any:
        """Declare (and cache) a publisher: repeated puts skip key resolution."""
        if len(self._publishers) >= _MAX_PUBLISHERS:
            _, oldest = self._publishers.popitem(last=False)
            with contextlib.suppress(zenoh.ZError):
                oldest.undeclare()
        cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        publisher: Any
        if is_heartbeat(key):
            publisher = self.session.declare_publisher(key, congestion_control=cc)
        else:
            publisher = zenoh.ext.declare_advanced_publisher(
                self.session,
                key,
                congestion_control=cc,
                cache=zenoh.ext.CacheConfig(CACHE_SAMPLES),
                sample_miss_detection=zenoh.ext.MissDetectionConfig(
                    heartbeat=None, sporadic_heartbeat=None
                ),
                publisher_detection=True,
            )
        self._publishers[(key, block)] = publisher
        return publisher

    def subscribe(
        self, key_expr: str | Sequence[str], *, history: bool = False
    ) -> _ZenohSubscription:
        self._check()
        exprs = [key_expr] if isinstance(key_expr, str) else key_expr
        return _ZenohSubscription(self, exprs, history)

    async def request(self, key: str, payload: bytes, *, timeout: float = 2.0) -> bytes:
        self._check()
        loop = self.loop
        future: asyncio.Future[bytes] = loop.create_future()

        def settle(result: bytes | BaseException) -> None:
            if future.done():
                return
            if isinstance(result, BaseException):
                future.set_exception(result)
            else:
                future.set_result(result)

        def on_reply(reply: zenoh.Reply) -> None:
            ok = reply.ok
            if ok is not None:
                _post(loop, settle, ok.payload.to_bytes())
            else:
                err = reply.err
                text = err.payload.to_string() if err is not None else "unknown error"
                _post(loop, settle, RequestFailedError(key, "zenoh_error", text))

        def on_done() -> None:
            _post(loop, settle, RequestTimeoutError(key, timeout))

        querier = self._queriers.get((key, timeout))
        if querier is None:
            querier = self._declare_querier(key, timeout)
        querier.get(Callback(on_reply, on_done, indirect=False), payload=payload)
        # Zenoh always calls on_done when the query ends (reply, timeout or session close).
        return await future

    async def serve(self, key_expr: str, handler: Handler) -> None:
        self._check()
        queue: _Inbox[zenoh.Query] = _Inbox(self.loop)
        on_query = queue.push

        queryable = self.session.declare_queryable(
            key_expr, Callback(on_query, indirect=False), complete=True
        )
        try:
            while True:
                query = await queue.get()
                await self._answer(query, handler)
        finally:
            with contextlib.suppress(zenoh.ZError):
                queryable.undeclare()  # type: ignore[no-untyped-call]

    async def _answer(self, query: zenoh.Query, handler: Handler) -> None:
        key = str(query.key_expr)
        payload = query.payload.to_bytes() if query.payload is not None else b""
        try:
            reply = await handler(key, payload)
            query.reply(query.key_expr, reply)
        except zenoh.ZError:
            pass  # the requester went away; nothing to answer
        finally:
            query.drop()  # type: ignore[no-untyped-call]

    async def declare_token(self, key: str) -> _ZenohToken:
        self._check()
        return _ZenohToken(self, key)

    async def watch_alive(self, key_expr: str) -> AsyncIterator[AliveEvent]:
        self._check()
        queue: _Inbox[AliveEvent] = _Inbox(self.loop)
        push = queue.push

        def on_sample(s: zenoh.Sample) -> None:
            push(AliveEvent(str(s.key_expr), s.kind == zenoh.SampleKind.PUT))

        sub = self.session.liveliness().declare_subscriber(
            key_expr, Callback(on_sample), history=True
        )
        try:
            while True:
                yield await queue.get()
        finally:
            with contextlib.suppress(zenoh.ZError):
                sub.undeclare()  # type: ignore[no-untyped-call]

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for item in list(self._closeables):
            await item.close()
        for declared in [*self._publishers.values(), *self._queriers.values()]:
            with contextlib.suppress(zenoh.ZError):
                declared.undeclare()
        self._publishers.clear()
        self._queriers.clear()
        await asyncio.to_thread(self.session.close)
