"""The in-memory bus: pub/sub with wildcards, request/reply, liveliness, typed helpers."""

from __future__ import annotations

import asyncio

import pytest

from cbdi.bus import LogSink, MemoryNetwork, messages, publish, request, serve
from cbdi.errors import BusClosedError, RequestFailedError, RequestTimeoutError, WireError
from cbdi.wire.common import ErrorReply
from cbdi.wire.world import ActionReply, ActionRequest, EpochAck


async def test_publish_reaches_matching_subscribers_only() -> None:
    net = MemoryNetwork()
    a, b = net.bus(), net.bus()
    sub_all = b.subscribe("cbdi/*/executor/ack")
    sub_one = b.subscribe("cbdi/r1/executor/ack")
    await a.publish("cbdi/r2/executor/ack", b"x")
    await a.publish("cbdi/r1/executor/ack", b"y")
    it_all, it_one = aiter(sub_all), aiter(sub_one)
    assert (await anext(it_all)).payload == b"x"
    assert (await anext(it_all)).key == "cbdi/r1/executor/ack"
    assert (await anext(it_one)).payload == b"y"
    assert sub_one.queue.empty()


async def test_request_reply_and_timeout() -> None:
    net = MemoryNetwork()
    server, client = net.bus(), net.bus()

    async def echo(key: str, payload: bytes) -> bytes:
        return key.encode() + b":" + payload

    task = asyncio.create_task(server.serve("svc/*", echo))
    await asyncio.sleep(0)
    assert await client.request("svc/a", b"hi") == b"svc/a:hi"
    with pytest.raises(RequestTimeoutError):
        await client.request("other/a", b"hi", timeout=0.05)
    task.cancel()


async def test_liveliness_reports_existing_and_new_tokens() -> None:
    net = MemoryNetwork()
    a, b = net.bus(), net.bus()
    first = await a.declare_token("cbdi/alive/world")
    watch = b.watch_alive("cbdi/alive/**")
    assert (await anext(watch)).alive
    second = await a.declare_token("cbdi/alive/r1/executor")
    event = await anext(watch)
    assert event.key == "cbdi/alive/r1/executor" and event.alive
    await second.close()
    event = await anext(watch)
    assert event.key == "cbdi/alive/r1/executor" and not event.alive
    await a.close()  # closing the bus drops its remaining tokens, like a dead process
    event = await anext(watch)
    assert event.key == "cbdi/alive/world" and not event.alive
    await first.close()
    await watch.aclose()


async def test_closed_bus_refuses_work() -> None:
    bus = MemoryNetwork().bus()
    await bus.close()
    with pytest.raises(BusClosedError):
        await bus.publish("a", b"")


async def test_typed_messages_skip_and_report_garbage() -> None:
    net = MemoryNetwork()
    a, b = net.bus(), net.bus()
    sink = LogSink()
    stream = messages(b, "cbdi/*/executor/ack", EpochAck, sink)
    await a.publish("cbdi/r1/executor/ack", b"\xc1garbage")
    await publish(a, "cbdi/r1/executor/ack", EpochAck(agent="r1", epoch=4))
    key, ack = await anext(stream)
    assert (key, ack.epoch) == ("cbdi/r1/executor/ack", 4)
    assert len(sink.errors) == 1 and isinstance(sink.errors[0][1], WireError)


async def test_typed_serve_answers_garbage_with_error_reply_and_keeps_serving() -> None:
    net = MemoryNetwork()
    server, client = net.bus(), net.bus()
    sink = LogSink()
    calls: list[str] = []

    async def handler(key: str, req: ActionRequest) -> ActionReply:
        calls.append(req.request_id)
        if req.action == "explode":
            raise RuntimeError("handler bug")
        return ActionReply(request_id=req.request_id, accepted=True)

    task = asyncio.create_task(serve(server, "cbdi/world/rpc/act", ActionRequest, handler, sink))
    await asyncio.sleep(0)
    from cbdi.wire import decode

    raw = await client.request("cbdi/world/rpc/act", b"not msgpack at all \xc1")
    err = decode(raw, ErrorReply)
    assert err.code == "bad_message" and "ActionRequest" in err.message
    with pytest.raises(RequestFailedError, match="internal"):
        await request(
            client,
            "cbdi/world/rpc/act",
            ActionRequest(agent="a", action="explode", request_id="boom"),
            ActionReply,
        )
    ok = await request(
        client,
        "cbdi/world/rpc/act",
        ActionRequest(agent="a", action="move", request_id="r2"),
        ActionReply,
    )
    assert ok.accepted and calls == ["boom", "r2"]
    assert len(sink.errors) == 2
    traced = [s.key for s in net.published if s.key.startswith("cbdi/trace/")]
    assert (
        "cbdi/trace/world/rpc/act/request" in traced and "cbdi/trace/world/rpc/act/reply" in traced
    )
    task.cancel()


async def test_inputs_merge_several_keys_in_order_and_skip_garbage() -> None:
    from cbdi.bus import inputs
    from cbdi.wire.common import RunFinished

    net = MemoryNetwork()
    a, b = net.bus(), net.bus()
    sink = LogSink()
    stream = inputs(b, ["cbdi/r1/executor/ack", "cbdi/world/events"], (EpochAck, RunFinished), sink)
    await publish(a, "cbdi/r1/executor/ack", EpochAck(agent="r1", epoch=1))
    await a.publish("cbdi/world/events", b"\xc1")
    await publish(a, "cbdi/world/events", RunFinished(reason="done", epoch=2, time=2.0))
    await publish(a, "cbdi/r1/executor/ack", EpochAck(agent="r1", epoch=2))
    got = [type(m).__name__ for _, m in [await anext(stream) for _ in range(3)]]
    assert got == ["EpochAck", "RunFinished", "EpochAck"] and len(sink.errors) == 1
