"""Two robots pass each other in a one-cell-wide corridor (issue 30), over real Zenoh,
in virtual time and in real time: robot2 carries the only item west to the bin, robot1
is parked in its way; blocked, robot2 asks robot1 under their group to make way, robot1
goes into the side pocket, and the run ends done (25 simulated seconds in lockstep).
Before robots could ask, it did not end within its 150 s limit in either mode."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cbdi.wire import decode
from cbdi.wire.agent import AgentReply, AgentRequest, DesireEvent
from cbdi_monitor.reader import read_messages
from tests_support import cbdi_up, free_port

pytestmark = pytest.mark.e2e

ASKED = "cbdi/trace/robot1/scheduler/rpc/request"


@pytest.mark.timeout(240)
@pytest.mark.parametrize(
    "mode", [["--speed", "0"], ["--no-lockstep", "--speed", "10"]], ids=["lockstep", "real-time"]
)
def test_robots_in_a_corridor_ask_each_other_to_make_way(tmp_path: Path, mode: list[str]) -> None:
    rec = tmp_path / "corridor.mcap"
    args = ["corridor-pass", *mode, "--json", "--quiet", "--port", str(free_port())]
    result = cbdi_up(*args, "--record", str(rec), timeout=200)
    assert result.returncode == 0, result.stderr[-3000:]
    summary = json.loads(result.stdout)
    assert summary["result"] == "done", summary["reason"]
    assert summary["stats"]["litter_recycled"] == 1

    recorded = list(read_messages(rec))
    asks = [decode(m.payload, AgentRequest) for m in recorded if m.key == ASKED + "/request"]
    replies = [decode(m.payload, AgentReply) for m in recorded if m.key == ASKED + "/reply"]
    assert [(a.from_agent, a.group, a.belief) for a in asks][:1] == [
        ("robot2", "recyclers", "(way_asked robot2)")
    ]
    assert replies and all(r.accepted for r in replies)
    events = [
        decode(m.payload, DesireEvent) for m in recorded if m.key == "cbdi/robot1/scheduler/desires"
    ]
    assert ("give_way", "achieved") in [(e.desire, e.event) for e in events]


@pytest.mark.timeout(240)
def test_asking_keeps_a_lockstep_run_the_same_whatever_the_start_order() -> None:
    """An ask lands before the asked agent's next epoch, however late it comes: a late
    scheduler and planner change nothing."""
    runs = [
        cbdi_up("corridor-pass", "--speed", "0", "--json", "--quiet", *late, timeout=200)
        for late in ([], ["--delay", "robot1/scheduler=2", "--delay", "robot2/planner=3"])
    ]
    assert all(r.returncode == 0 for r in runs), runs[-1].stderr[-3000:]
    first, again = (json.loads(r.stdout) for r in runs)
    assert first["result"] == again["result"] == "done"
    assert first["trace_digest"] == again["trace_digest"]
