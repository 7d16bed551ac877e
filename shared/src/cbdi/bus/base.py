"""The one bus interface of cbdi: publish, subscribe, request/reply and liveliness.

Services only ever talk to a `Bus`. `ZenohBus` is the real one (client of a router, or a
peer); `MemoryBus` is in-process and deterministic, for tests of logic. Payloads are bytes
here; typed messages are encoded and decoded by `cbdi.bus.typed` on top of this.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

__all__ = ["AliveEvent", "Bus", "Handler", "Sample", "Subscription", "Token"]


@dataclass(frozen=True, slots=True)
class Sample:
    """A published payload, the concrete key it was published on, and the sender's stamp.

    `seq` counts the sender's publications on this key (from 1) and `sent_ns` is the
    sender's wall time at publication (ns since the epoch); `order` numbers the sender's
    publications over all its keys (samples of several subscriptions may arrive out of
    that order); all 0 if the sender gave none.
    """

    key: str
    payload: bytes
    seq: int = 0
    sent_ns: int = 0
    order: int = 0


@dataclass(frozen=True, slots=True)
class AliveEvent:
    """A liveliness token appeared (`alive`) or vanished (not `alive`)."""

    key: str
    alive: bool


# A request handler gets the concrete key and the request payload, returns the reply.
Handler = Callable[[str, bytes], Awaitable[bytes]]


class Subscription(Protocol):
    """An open subscription: iterate it for samples, close it when done."""

    def __aiter__(self) -> AsyncIterator[Sample]: ...
    async def close(self) -> None: ...


class Token(Protocol):
    """A declared liveliness token; undeclare it with `close`."""

    async def close(self) -> None: ...


class Bus(Protocol):
    """Everything a service may do on the network.

    `sent` counts publications per key (what a recorder must find in its file).
    """

    sent: Counter[str]
    # Publications under way: one that stays above 0 while the loop stands is a send
    # waiting for room on the network (congestion), read by the stall watcher's thread.
    sending: int

    async def publish(self, key: str, payload: bytes, *, block: bool = False) -> None:
        """Publish `payload` on `key`; `block` (commands, plans) never drops under load."""
        ...

    def pulse(self, key: str, payload: bytes) -> None:
        """Publish `payload` on `key` now, from any thread, even while the event loop
        stands; best effort (dropped under congestion), neither counted in `sent` nor
        kept for late joiners: for liveness signals (a stalled loop's heartbeat) only."""
        ...

    def subscribe(self, key_expr: str | Sequence[str], *, history: bool = False) -> Subscription:
        """Subscribe to one or several key expressions (wildcards allowed) in one queue.

        Samples of all of them arrive in one stream, in the order they were received, and
        wait in the queue until iterated; nothing is dropped. With `history`, samples
        published before the subscription that publishers still hold (their recovery
        caches) come first: what a restarted recorder missed.
        """
        ...

    async def request(self, key: str, payload: bytes, *, timeout: float = 2.0) -> bytes:
        """Send a request and return the first reply; raise RequestTimeoutError if none."""
        ...

    async def serve(self, key_expr: str, handler: Handler) -> None:
        """Answer requests on `key_expr` with `handler` until cancelled."""
        ...

    async def declare_token(self, key: str) -> Token:
        """Declare a liveliness token that lives until closed or until this bus dies."""
        ...

    def watch_alive(self, key_expr: str) -> AsyncIterator[AliveEvent]:
        """Yield liveliness changes under `key_expr`, starting with tokens alive now."""
        ...

    async def close(self) -> None:
        """Close the bus and everything declared on it; idempotent."""
        ...
