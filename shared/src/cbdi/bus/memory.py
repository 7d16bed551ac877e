"""An in-process, deterministic `Bus` for unit tests of logic.

Several `MemoryBus` endpoints attached to one `MemoryNetwork` see each other's
publications, requests and tokens, as services on one Zenoh network would. Delivery is
immediate and in publication order. Key matching uses Zenoh's own key expression rules
(`cbdi.keys.matches`).
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections import Counter
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field

from cbdi.bus.base import AliveEvent, Handler, Sample
from cbdi.errors import BusClosedError, RequestTimeoutError
from cbdi.keys import matches as _matches

__all__ = ["MemoryBus", "MemoryNetwork"]


@dataclass
class MemoryNetwork:
    """The shared medium of a group of `MemoryBus` endpoints."""

    subscribers: list[_MemorySubscription] = field(default_factory=list)
    servers: list[tuple[str, Handler]] = field(default_factory=list)
    tokens: dict[str, int] = field(default_factory=dict)
    watchers: list[tuple[str, asyncio.Queue[AliveEvent]]] = field(default_factory=list)
    published: list[Sample] = field(default_factory=list)

    def bus(self) -> MemoryBus:
        """Attach a new endpoint to this network."""
        return MemoryBus(self)

    def _set_token(self, key: str, delta: int) -> None:
        before = self.tokens.get(key, 0)
        after = before + delta
        if after:
            self.tokens[key] = after
        else:
            self.tokens.pop(key, None)
        if bool(before) != bool(after):
            for expr, queue in self.watchers:
                if _matches(expr, key):
                    queue.put_nowait(AliveEvent(key, bool(after)))


class _MemorySubscription:
    def __init__(self, network: MemoryNetwork, key_exprs: Sequence[str]) -> None:
        self.key_exprs = list(key_exprs)
        self.queue: asyncio.Queue[Sample | None] = asyncio.Queue()
        try:  # where a pulse from another thread is handed over
            self.loop: asyncio.AbstractEventLoop | None = asyncio.get_running_loop()
        except RuntimeError:
            self.loop = None
        self._network = network
        network.subscribers.append(self)

    def __aiter__(self) -> AsyncIterator[Sample]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[Sample]:
        while (sample := await self.queue.get()) is not None:
            yield sample

    async def close(self) -> None:
        if self in self._network.subscribers:
            self._network.subscribers.remove(self)
            self.queue.put_nowait(None)


class _MemoryToken:
    def __init__(self, network: MemoryNetwork, key: str) -> None:
        self._network = network
        self.key = key
        self.open = True
        network._set_token(key, +1)

    async def close(self) -> None:
        if self.open:
            self.open = False
            self._network._set_token(self.key, -1)


class MemoryBus:
    """One endpoint on a `MemoryNetwork`; implements `cbdi.bus.Bus`."""

    def __init__(self, network: MemoryNetwork | None = None) -> None:
        self.network = network or MemoryNetwork()
        self._closed = False
        self._subscriptions: list[_MemorySubscription] = []
        self._tokens: list[_MemoryToken] = []
        self.sent: Counter[str] = Counter()
        self.sending = 0  # a send here never waits for room
        self.published = 0

    def _check(self) -> None:
        if self._closed:
            raise BusClosedError("memory bus is closed")

    async def publish(self, key: str, payload: bytes, *, block: bool = False) -> None:
        self._check()
        seq = self.sent[key] = self.sent[key] + 1
        self.published += 1
        sample = Sample(key, bytes(payload), seq, time.time_ns(), self.published)
        self.network.published.append(sample)
        for sub in list(self.network.subscribers):
            if any(_matches(expr, key) for expr in sub.key_exprs):
                sub.queue.put_nowait(sample)

    def pulse(self, key: str, payload: bytes) -> None:
        if self._closed:
            return
        sample = Sample(key, bytes(payload), 0, time.time_ns(), 0)
        for sub in list(self.network.subscribers):
            if not any(_matches(expr, key) for expr in sub.key_exprs):
                continue
            if sub.loop is None:
                sub.queue.put_nowait(sample)
            else:
                with contextlib.suppress(RuntimeError):  # its loop closed: nobody listens
                    sub.loop.call_soon_threadsafe(sub.queue.put_nowait, sample)

    def subscribe(
        self, key_expr: str | Sequence[str], *, history: bool = False
    ) -> _MemorySubscription:
        # `history`: nothing is lost in memory, and a subscription starts with what comes.
        self._check()
        exprs = [key_expr] if isinstance(key_expr, str) else key_expr
        sub = _MemorySubscription(self.network, exprs)
        self._subscriptions.append(sub)
        return sub

    async def request(self, key: str, payload: bytes, *, timeout: float = 2.0) -> bytes:
        self._check()
        for expr, handler in list(self.network.servers):
            if _matches(expr, key):
                async with asyncio.timeout(timeout):
                    return await handler(key, bytes(payload))
        raise RequestTimeoutError(key, timeout)

    async def serve(self, key_expr: str, handler: Handler) -> None:
        self._check()
        entry = (key_expr, handler)
        self.network.servers.append(entry)
        try:
            await asyncio.Event().wait()
        finally:
            self.network.servers.remove(entry)

    async def declare_token(self, key: str) -> _MemoryToken:
        self._check()
        token = _MemoryToken(self.network, key)
        self._tokens.append(token)
        return token

    async def watch_alive(self, key_expr: str) -> AsyncIterator[AliveEvent]:
        self._check()
        queue: asyncio.Queue[AliveEvent] = asyncio.Queue()
        for key in sorted(self.network.tokens):
            if _matches(key_expr, key):
                queue.put_nowait(AliveEvent(key, True))
        entry = (key_expr, queue)
        self.network.watchers.append(entry)
        try:
            while True:
                yield await queue.get()
        finally:
            self.network.watchers.remove(entry)

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for sub in self._subscriptions:
            await sub.close()
        for token in self._tokens:
            await token.close()
