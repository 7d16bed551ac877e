"""Multi-agent requests: allowed groups check and add beliefs and desires; others are refused."""

from __future__ import annotations

import pytest

from cbdi import keys
from cbdi.beliefs import fact
from cbdi.bus import BusConfig, open_bus, request
from cbdi.wire.agent import AgentReply, AgentRequest
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.requests import serve_request
from tests_support import REPO, wait_for

AGENT = REPO / "domains/recycling/agents/recycler.toml"


def ask(op: str, group: str = "recyclers", **kw: object) -> AgentRequest:
    return AgentRequest(from_agent="robot2", group=group, op=op, **kw)  # type: ignore[arg-type]


def test_allowed_group_checks_and_adds() -> None:
    mind = Mind(load_agent(AGENT, "robot1"))
    assert not serve_request(mind, ask("check_belief", belief="(recycled pla1)")).holds
    assert serve_request(mind, ask("add_belief", belief="(recycled pla1)")).accepted
    assert mind.beliefs.holds(fact("recycled", "pla1")) and mind.refire
    assert serve_request(mind, ask("check_belief", belief="(recycled pla1)")).holds
    added = serve_request(
        mind,
        ask("add_desire", desire="help", goal=["(in robot1 c_1_1)"], priority=0.3, deadline=20),
    )
    assert added.accepted and mind.desires["help"].deadline == 20.0
    assert serve_request(mind, ask("check_desire", desire="help")).holds
    assert [e.event for e in mind.requested] == ["added"]


def test_beliefs_and_desires_are_removed() -> None:
    mind = Mind(load_agent(AGENT, "robot1"))
    serve_request(mind, ask("add_belief", belief="(recycled pla1)"))
    removed = serve_request(mind, ask("del_belief", belief="(recycled pla1)"))
    assert removed.accepted and not mind.beliefs.holds(fact("recycled", "pla1"))
    serve_request(mind, ask("add_desire", desire="help", goal=["(in {self} c_1_1)"]))
    assert mind.desires["help"].goal == (fact("in", "robot1", "c_1_1"),)
    assert serve_request(mind, ask("del_desire", desire="help")).accepted
    assert mind.withdrawn == {"help": "removed by robot2"}


def test_a_desire_is_taken_with_its_precondition_and_context() -> None:
    mind = Mind(load_agent(AGENT, "robot1"))
    reply = serve_request(
        mind,
        ask(
            "add_desire",
            desire="fetch",
            goal=["(holding robot1 pla1)"],
            precondition=[["(litter_pose pla1 c_2_2)"], ["(map_loaded)"]],
            context=[["(not (recycled pla1))", "(< (loaded_amount robot1) 3)"]],
        ),
    )
    assert reply.accepted, reply.reason
    d = mind.desires["fetch"]
    assert [len(c) for c in d.precondition] == [1, 1]
    assert [lit.check for lit in d.context[0]] == ["F", "LT"]


def test_everything_else_is_refused_with_a_reason() -> None:
    mind = Mind(load_agent(AGENT, "robot1"))
    refused = serve_request(mind, ask("add_belief", group="strangers", belief="(recycled pla3)"))
    assert not refused.accepted and "not allowed" in refused.reason
    assert not mind.beliefs.holds(fact("recycled", "pla3"))
    assert "unknown op" in serve_request(mind, ask("erase")).reason
    assert "missing ')'" in serve_request(mind, ask("add_belief", belief="(x")).reason
    assert "needs a desire" in serve_request(mind, ask("add_desire", desire="d")).reason
    typo = serve_request(mind, ask("add_belief", belief="(holdin robot1 pla1)"))
    assert not typo.accepted and "'holdin' is not declared" in typo.reason
    arity = serve_request(mind, ask("add_desire", desire="d", goal=["(in robot1)"]))
    assert "goal[0]: 'in' takes 2 argument(s), got 1" in arity.reason
    bad_context = serve_request(
        mind, ask("add_desire", desire="d", goal=["(map_loaded)"], context=[["(nope)"]])
    )
    assert "context[0][0]: 'nope' is not declared" in bad_context.reason
    assert (
        "no desire 'ghost' is held" in serve_request(mind, ask("del_desire", desire="ghost")).reason
    )
    serve_request(mind, ask("add_desire", desire="d", goal=["(map_loaded)"]))
    again = serve_request(mind, ask("add_desire", desire="d", goal=["(map_loaded)"]))
    assert not again.accepted and "already held" in again.reason
    assert "d" not in mind.withdrawn


@pytest.mark.e2e
async def test_requests_over_zenoh(router: str, spawn: object) -> None:
    proc = spawn(
        "scheduler",
        "cbdi-scheduler",
        "--agent",
        "robot1",
        "--agent-file",  # type: ignore[operator]
        str(AGENT),
        "--no-load-map",
        env={"CBDI_CONNECT": router},
    )
    wait_for(lambda: "event=ready" in proc.output(), what="scheduler ready")
    key = keys.component_rpc("robot1", "scheduler", "request")
    bus = await open_bus(BusConfig(connect=(router,)))
    try:
        ok = await request(bus, key, ask("add_belief", belief="(recycled pla9)"), AgentReply)
        check = await request(bus, key, ask("check_belief", belief="(recycled pla9)"), AgentReply)
        no = await request(
            bus, key, ask("check_belief", group="x", belief="(recycled pla9)"), AgentReply
        )
    finally:
        await bus.close()
    assert ok.accepted and check.holds and not no.accepted
    wait_for(lambda: "accepted=False" in proc.output(), what="the refusal to be logged")
