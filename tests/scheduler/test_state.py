"""What `cbdi ctl show` gets: the agent's beliefs, desires, intention and its plan."""

from __future__ import annotations

import re

import pytest
from msgspec.structs import replace

from cbdi.ctl import UsageError, format_state, split_literals
from cbdi.wire import decode, encode
from cbdi.wire.agent import ActionStatus, AgentRequest, AgentState, PartialPlan, PlanStep
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.requests import serve_request
from cbdi_scheduler.state import PlanLog, agent_state
from tests_support import REPO

AGENT = REPO / "domains/recycling/agents/recycler.toml"


def test_the_state_shows_the_intention_its_steps_and_their_status() -> None:
    from tests.scheduler.test_mind import percepts

    mind = Mind(load_agent(AGENT, "robot1"))
    mind.on_percepts(percepts(0, [("pla1", (1, 1))]))
    step = PlanStep(
        step_id="a", action="move", args=["robot1", "c_0_1", "c_1_1"], start=0, duration=1
    )
    plan = PartialPlan(agent="robot1", plan_id="p1", baseline="", steps=[step])
    log = PlanLog()
    for c in mind.on_plan(plan).commands:
        assert c.plan is not None
        log.sent(c.plan, mind.intentions.current.steps)  # type: ignore[union-attr]
    status = ActionStatus(
        agent="robot1",
        plan_id="p1",
        step_id="a",
        action="move",
        status="running",
        reason="",
        time=0.0,
    )
    log.reported(status)
    serve_request(
        mind,
        AgentRequest(
            from_agent="op",
            group="operator",
            op="add_desire",
            desire="later",
            goal=["(in robot1 c_6_6)"],
            priority=0.1,
            context=[["(not (holding robot1 pla1))", "(< (loaded_amount robot1) 3)"]],
        ),
    )
    state = decode(encode(agent_state(mind, log)), AgentState)  # it crosses the wire
    assert state.intention is not None and state.intention.desire == "recycle"
    assert [(s.action, s.status) for s in state.intention.steps] == [
        ("(move robot1 c_0_1 c_1_1)", "running")
    ]
    assert [d.name for d in state.desires] == ["later", "recycle"]
    later = state.desires[0]
    assert later.deadline is None
    assert later.context == [["(not (holding robot1 pla1))", "(< (loaded_amount robot1) 3)"]]
    assert "(litter_pose pla1 c_1_1)" in state.beliefs
    text = format_state(state)
    assert "intention: recycle (plan p1)" in text and "running" in text
    assert "context [(not (holding robot1 pla1)) (< (loaded_amount robot1) 3)]" in text
    assert not agent_state(mind, log, beliefs=False).beliefs
    # A failed search: the state says what it failed on and when it is tried again.
    mind.on_status(replace(status, status="refused", reason="(in robot1 c_0_1) does not hold"))
    mind.on_search_failed("no plan from the beliefs")
    waiting = agent_state(mind, log, beliefs=False).intention
    assert waiting is not None and waiting.retry == "retry after: no plan from the beliefs"
    assert waiting.retry_when.startswith("when the beliefs change; its deadline is t=")
    assert (
        "  retry after: no plan from the beliefs; searching again when the beliefs change"
        in format_state(agent_state(mind, log, beliefs=False))
    )


def test_literals_split_at_the_top_level_and_bad_ones_say_why() -> None:
    assert split_literals("(a b) (not (c d))  (= (f x) 3)") == [
        "(a b)",
        "(not (c d))",
        "(= (f x) 3)",
    ]
    for bad, why in (("(a b", "missing ')'"), ("a b)", "expected literals"), ("", "at least")):
        with pytest.raises(UsageError, match=re.escape(why)):
            split_literals(bad)


def test_ctl_tells_an_event_as_an_event_request() -> None:
    from cbdi.ctl_args import build_request, parser

    args = parser().parse_args(["belief", "event", "robot1", "(bumped robot1)"])
    req = build_request(args)
    assert (req.op, req.belief, req.group) == ("event", "(bumped robot1)", "operator")
