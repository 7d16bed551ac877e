"""A higher-priority desire preempts the running one under clean_preempt: the executor
stops safely (early arrest), the new desire is pursued, then recycling resumes."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from cbdi import keys
from cbdi.bus import LogSink, messages, request
from cbdi.security.login import open_as
from cbdi.wire import decode
from cbdi.wire.agent import (
    ActionStatus,
    AgentReply,
    AgentRequest,
    ArrestReport,
    DesireEvent,
    EarlyArrest,
)
from cbdi.wire.world import WorldSnapshot
from cbdi_monitor.reader import read_messages
from tests_support import BIN, Proc, free_port, wait_for

pytestmark = pytest.mark.e2e


CORNERS = [(0, 6), (6, 0)]  # off the people's loops: no person stands on the goal


async def ask_to_go(endpoint: str, after: float = 4.0) -> AgentReply:
    """Ask robot1 (as an operator of its group) to go to the corner farthest from it, once
    `after` simulated seconds passed (on its way to the litter, however loaded the machine).
    """
    bus = await open_as("operator", [endpoint])  # the run's operator (docs/security.md)
    try:
        snapshots = messages(bus, keys.SNAPSHOT, WorldSnapshot, LogSink())
        while True:
            _, snap = await asyncio.wait_for(anext(snapshots), 30)
            if snap.time >= after:
                break
        x, y = next(a.cell for a in snap.agents if a.name == "robot1")
        far = max(CORNERS, key=lambda c: abs(c[0] - x) + abs(c[1] - y))
        urgent = AgentRequest(
            from_agent="operator",
            group="operator",
            op="add_desire",
            desire="clear_the_way",
            goal=[f"(in robot1 c_{far[0]}_{far[1]})"],
            priority=0.95,
            deadline=200,
        )
        key = keys.agent_request("robot1", "operator")
        return await request(bus, key, urgent, AgentReply, timeout=10)
    finally:
        await bus.close()


def test_a_higher_priority_desire_preempts_cleanly(tmp_path: Path) -> None:
    port, rec = free_port(), tmp_path / "preempt.mcap"
    argv = [str(BIN / "cbdi"), "up", "paper-7x7", "--port", str(port), "--json", "--quiet"]
    launcher = Proc([*argv, "--record", str(rec)], tmp_path / "up.log")
    try:
        wait_for(
            lambda: "started service=robot1/executor" in launcher.output(),
            timeout=60,
            what="the run to start",
        )
        reply = asyncio.run(ask_to_go(f"tcp/127.0.0.1:{port}"))
        assert reply.accepted, reply.reason
        wait_for(lambda: not launcher.alive(), timeout=180, what="the run to end")
    finally:
        code = launcher.stop()
    assert code == 0, launcher.output()[-3000:]  # 0: all litter recycled (`until done`)

    recorded = list(read_messages(rec))

    def of(key: str, cls: type) -> list:
        return [(m.log_ns, decode(m.payload, cls)) for m in recorded if m.key == key]

    desires = of(keys.scheduler_desires("robot1"), DesireEvent)
    arrests = of(keys.scheduler_arrest("robot1"), EarlyArrest)
    stopped = of(keys.executor_arrested("robot1"), ArrestReport)
    statuses = of(keys.executor_status("robot1"), ActionStatus)
    urgent = [(t, e.event) for t, e in desires if e.desire == "clear_the_way"]
    ends = ("activated", "achieved", "dropped")  # "waiting": a person stood on the goal
    assert [e for _, e in urgent if e in ends][:2] == ["activated", "achieved"], urgent
    activated = next(t for t, e in urgent if e == "activated")
    assert arrests and stopped
    stop_t, report = next((t, r) for t, r in stopped if t <= activated)
    # Clean preemption: the new desire starts only once the executor stopped, and
    # nothing of the preempted plan started after the stop.
    assert report.plan_id
    assert not [
        s
        for t, s in statuses
        if t > stop_t and s.plan_id == report.plan_id and s.status == "running"
    ]
    assert not [s for t, s in statuses if s.status == "failed" and t <= activated]
    resumed = [t for t, e in desires if e.desire == "recycle" and e.event == "activated"]
    assert any(t > activated for t in resumed)
