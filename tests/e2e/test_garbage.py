"""Garbage on every endpoint: each service answers or reports it, and stays alive."""

from __future__ import annotations

import asyncio

import msgpack
import pytest

from cbdi import keys
from cbdi.bus import BusConfig, LogSink, messages, open_bus, request
from cbdi.errors import RequestFailedError
from cbdi.wire import decode, encode
from cbdi.wire.common import ErrorReply, ErrorReport
from cbdi.wire.world import (
    ActionReply,
    ActionRequest,
    EpochAck,
    StatsRequest,
    WorldInfo,
    WorldInfoRequest,
    WorldStats,
)
from tests_support import REPO, wait_for

pytestmark = pytest.mark.e2e

MAP = str(REPO / "domains/recycling/maps/paper-7x7.toml")
GARBAGE = [
    b"",
    b"\xc1\xc1\xc1",
    b"not msgpack",
    msgpack.packb([1, 2, 3]),
    msgpack.packb({"schema": "cbdi.world.ActionRequest/1", "agent": 5}),
    encode(EpochAck(agent="robot1", epoch=1)),
]  # a valid message of the wrong type


async def test_services_survive_garbage_on_every_endpoint(router: str, spawn: object) -> None:
    env = {"CBDI_CONNECT": router}
    world = spawn(
        "world",
        "cbdi-world",
        "--simulator",
        "recycling",
        "--map",
        MAP,
        "--agent",
        "robot1",
        "--speed",
        "20",  # type: ignore[operator]
        "--no-stop-when-done",
        env=env,
    )
    agent = spawn("agent", "cbdi-scripted-agent", "--agent", "robot1", env=env)  # type: ignore[operator]
    wait_for(
        lambda: "event=ready" in world.output() and "event=ready" in agent.output(),
        what="services ready",
    )
    bus = await open_bus(BusConfig(connect=(router,)))
    try:
        reports = messages(bus, "cbdi/**/errors", ErrorReport, LogSink())
        await asyncio.sleep(0.3)
        for name in ("act", "stats", "info"):
            for payload in GARBAGE:
                reply = decode(
                    await bus.request(keys.world_rpc(name), payload, timeout=5), ErrorReply
                )
                assert reply.code == "bad_message", (name, payload, reply)
        for payload in GARBAGE:  # streams the services subscribe to
            await bus.publish(keys.agent_ack("robot1"), payload, block=True)
            await bus.publish(keys.world_percepts("robot1"), payload, block=True)
            await bus.publish(keys.world_outcomes("robot1"), payload, block=True)
        await bus.publish(
            keys.agent_ack("intruder"), encode(EpochAck(agent="intruder", epoch=0)), block=True
        )

        with pytest.raises(RequestFailedError, match="unknown_agent"):
            await request(
                bus,
                keys.world_rpc("act"),
                ActionRequest(agent="intruder", action="move", request_id="x", target=(1, 1)),
                ActionReply,
            )
        with pytest.raises(RequestFailedError, match="unknown_agent"):
            await request(bus, keys.world_rpc("stats"), StatsRequest(agent="intruder"), WorldStats)
        rejected = await request(
            bus,
            keys.world_rpc("act"),
            ActionRequest(agent="robot1", action="fly", request_id="y"),
            ActionReply,
        )
        assert not rejected.accepted and "unknown action" in rejected.reason
        far = await request(
            bus,
            keys.world_rpc("act"),
            ActionRequest(agent="robot1", action="move", request_id="z", target=(6, 6)),
            ActionReply,
        )
        assert not far.accepted

        seen: dict[str, int] = {}
        while seen.get("world", 0) < 3 * len(GARBAGE) or seen.get("robot1/executor", 0) < 3:
            _, report = await asyncio.wait_for(anext(reports), 10)
            seen[report.service] = seen.get(report.service, 0) + 1
        info = await request(bus, keys.world_rpc("info"), WorldInfoRequest(), WorldInfo)
        assert info.map_name == "paper-7x7"
    finally:
        await bus.close()
    assert world.alive() and agent.alive()
    assert "event=bad_input" in world.output() and "event=bad_input" in agent.output()
