"""The Zenoh bus between real sessions through a real `cbdi router` process."""

from __future__ import annotations

import asyncio
import time

import pytest

from cbdi.bus import BusConfig, open_bus
from cbdi.bus.zenoh_bus import RECOVERY_PERIOD
from cbdi.errors import ConfigError, RequestTimeoutError
from tests_support import free_port

pytestmark = pytest.mark.e2e


async def test_pubsub_request_and_liveliness_through_router(router: str) -> None:
    cfg = BusConfig(connect=(router,))
    a, b = await open_bus(cfg), await open_bus(cfg)
    try:
        sub = b.subscribe("cbdi/test/**")
        watch = b.watch_alive("cbdi/alive/test/**")
        await asyncio.sleep(0.3)
        for i in range(50):
            await a.publish(f"cbdi/test/{i % 3}", bytes([i]), block=True)
        it = aiter(sub)
        got = [await asyncio.wait_for(anext(it), 30) for _ in range(50)]
        assert [s.payload[0] for s in got] == list(range(50))  # in order, none lost

        async def echo(key: str, payload: bytes) -> bytes:
            return payload[::-1]

        server = asyncio.create_task(b.serve("cbdi/test/rpc/echo", echo))
        await asyncio.sleep(0.3)
        assert await a.request("cbdi/test/rpc/echo", b"abc", timeout=5) == b"cba"
        with pytest.raises(RequestTimeoutError):
            await a.request("cbdi/test/rpc/nobody", b"x", timeout=0.3)

        token = await a.declare_token("cbdi/alive/test/one")
        event = await asyncio.wait_for(anext(watch), 30)
        assert event.alive and event.key == "cbdi/alive/test/one"
        await token.close()
        event = await asyncio.wait_for(anext(watch), 30)
        assert not event.alive
        server.cancel()
        await watch.aclose()
    finally:
        await a.close()
        await b.close()


async def test_tokens_vanish_when_the_holder_closes(router: str) -> None:
    cfg = BusConfig(connect=(router,))
    a, b = await open_bus(cfg), await open_bus(cfg)
    try:
        watch = b.watch_alive("cbdi/alive/**")
        await a.declare_token("cbdi/alive/test/holder")
        seen = set()
        while "cbdi/alive/test/holder" not in seen:
            seen.add((await asyncio.wait_for(anext(watch), 30)).key)
        await a.close()  # the session ends: its token must go, as after a crash
        while True:
            event = await asyncio.wait_for(anext(watch), 30)
            if event.key == "cbdi/alive/test/holder":
                assert not event.alive
                break
        await watch.aclose()
    finally:
        await a.close()
        await b.close()


async def test_peer_mode_without_router() -> None:
    port = free_port()
    a = await open_bus(BusConfig(mode="peer", connect=(), listen=(f"tcp/127.0.0.1:{port}",)))
    b = await open_bus(BusConfig(mode="peer", connect=(f"tcp/127.0.0.1:{port}",)))
    try:
        sub = b.subscribe("cbdi/peer/x")
        await asyncio.sleep(0.5)
        await a.publish("cbdi/peer/x", b"hi", block=True)
        assert (await asyncio.wait_for(anext(aiter(sub)), 30)).payload == b"hi"
    finally:
        await a.close()
        await b.close()


async def test_no_router_is_a_clear_error() -> None:
    cfg = BusConfig(connect=(f"tcp/127.0.0.1:{free_port()}",), connect_timeout=0.5)
    with pytest.raises(ConfigError, match="cannot join Zenoh"):
        await open_bus(cfg)


async def test_what_is_published_while_the_router_is_down_arrives_after_its_restart(
    spawn: object,
) -> None:
    """Advanced pub/sub: a subscriber recovers, in order, what a publisher sent while the
    router was killed (including the last samples, with nothing sent after them); a
    subscriber that joins later gets none of what was sent before it joined, and a
    subscription with history gets that too."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"

    def start_router() -> object:
        proc = spawn("router", "cbdi", "router", "--listen", endpoint)  # type: ignore[operator]
        for _ in range(300):
            if "event=ready" in proc.output():
                return proc
            time.sleep(0.05)
        raise AssertionError(proc.output())

    first = start_router()
    cfg = BusConfig(connect=(endpoint,), connect_timeout=30)
    a, b = await open_bus(cfg), await open_bus(cfg)
    try:
        sub = b.subscribe("cbdi/test/**")
        await asyncio.sleep(0.5)
        for i in range(10):
            await a.publish("cbdi/test/x", bytes([i]), block=True)
        it = aiter(sub)
        got = [(await asyncio.wait_for(anext(it), 10)).payload[0] for _ in range(10)]
        first.popen.kill()  # type: ignore[attr-defined]
        first.popen.wait()  # type: ignore[attr-defined]
        await asyncio.sleep(0.5)
        for i in range(10, 20):  # into the void: no router
            await a.publish("cbdi/test/x", bytes([i]), block=True)
        start_router()
        got += [(await asyncio.wait_for(anext(it), 30)).payload[0] for _ in range(10)]
        assert got == list(range(20))
        late = b.subscribe("cbdi/test/**")
        past = b.subscribe("cbdi/test/**", history=True)
        await asyncio.sleep(1.5 * RECOVERY_PERIOD.total_seconds())  # its queries came
        await a.publish("cbdi/test/x", bytes([20]), block=True)
        assert (await asyncio.wait_for(anext(aiter(late)), 10)).payload[0] == 20
        history = [(await asyncio.wait_for(anext(aiter(past)), 10)).payload[0] for _ in range(21)]
        assert history == list(range(21))
    finally:
        await a.close()
        await b.close()
