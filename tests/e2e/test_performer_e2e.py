"""A performer in its own process (real Zenoh): the recycling domain with `move` renamed
`drive`, which the world does not perform. The agent file names a performer for it; the
performer drives the robot through the world's own `move`, and the run recycles
everything. Without the performer named, `cbdi up` refuses to start (test_config_files)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests_support import BIN, REPO, Proc, free_port

pytestmark = pytest.mark.e2e

PERFORMER = '''
import asyncio, itertools, sys
from cbdi import keys
from cbdi.bus import LogSink, messages, request
from cbdi.performer import ActionCall, Outcome, serve_performer
from cbdi.security.login import open_as
from cbdi.wire.world import ActionOutcome, ActionReply, ActionRequest

class Drive:
    """(drive ?r ?from ?to): ask the simulated world to move there, wait for the end."""
    def __init__(self, bus):
        self.bus, self.ids = bus, itertools.count(1)
    async def perform(self, call: ActionCall) -> Outcome:
        print("called", call.args[2], flush=True)
        x, y = (int(v) for v in call.args[2].split("_")[1:])
        rid = f"drive-{next(self.ids)}"
        ends = messages(self.bus, keys.world_outcomes(call.agent), ActionOutcome, LogSink())
        req = ActionRequest(agent=call.agent, action="move", request_id=rid, target=(x, y))
        reply = await request(self.bus, keys.world_act(call.agent), req, ActionReply)
        if not reply.accepted:
            return Outcome.failure(reply.reason)
        async for _key, out in ends:
            if out.request_id == rid:
                print("drove", call.args[2], out.status, flush=True)
                ok = out.status == "succeeded"
                return Outcome.success() if ok else Outcome.failure(out.reason)
        return Outcome.failure("no outcome")

async def main():
    # The router comes up with `cbdi up`, started after us; robot1's performer's
    # credentials with it.
    bus = await open_as("robot1/performer", [sys.argv[1]], timeout=120.0)
    print("serving", flush=True)
    await serve_performer(bus, "robot1", "drive", Drive(bus))

asyncio.run(main())
'''


def test_a_performer_process_carries_out_an_action_the_world_does_not(tmp_path: Path) -> None:
    domain = tmp_path / "domain.pddl"
    text = (REPO / "domains/recycling/pddl/domain.pddl").read_text()
    domain.write_text(text.replace("(:durative-action move", "(:durative-action drive"))
    agent = (REPO / "domains/recycling/agents/recycler.toml").read_text()
    agent = agent.replace('domain = "../pddl/domain.pddl"', f'domain = "{domain}"')
    (tmp_path / "agent.toml").write_text('performers = ["drive"]\n' + agent)
    scenario = tmp_path / "drive.toml"
    scenario.write_text(
        f'name = "drive"\nmap = "{REPO / "domains/recycling/maps/paper-7x7.toml"}"\n'
        '[run]\nsimulator = "recycling"\nspeed = 2.0\nmax_time = 400.0\n'
        '[[agents]]\nname = "robot1"\nkind = "bdi"\n'
        f'agent_file = "{tmp_path / "agent.toml"}"\n'
    )
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    script = tmp_path / "drive.py"
    script.write_text(PERFORMER)
    argv = [str(BIN / "cbdi"), "up", str(scenario), "--port", str(port), "--json", "--quiet"]
    performer = Proc([sys.executable, str(script), endpoint], tmp_path / "drive.log")
    try:
        with (tmp_path / "up.log").open("w") as log:
            done = subprocess.run(
                argv, stdout=subprocess.PIPE, stderr=log, text=True, timeout=600, cwd=REPO
            )
        summary = json.loads(done.stdout)
    finally:
        drove = performer.output()
        performer.stop()
    up_log = (tmp_path / "up.log").read_text()
    assert done.returncode == 0 and summary["result"] == "done", up_log[-3000:]
    assert drove.count("drove") >= 5, drove[-2000:]
    assert summary["stats"]["agents"]["robot1"]["recycled"] == 3
    assert summary["stats"]["agents"]["robot1"]["moves"] >= 5
    # The summary counts the steps started, whoever performed them: every drive the
    # performer was called for (the world saw only its own `move`s; one started as the
    # world ended the run may be reported too late to count), and the world's actions.
    performed = summary["performed"]["robot1"]
    called = drove.count("called")
    assert called - 1 <= performed["drive"] <= called, (performed, drove[-2000:])
    assert performed["litter_pickup"] == 3 and performed["recycle"] >= 1, performed
