"""The mind: the BDI cycle of the paper's recycler on percepts, plans and statuses."""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path

from cbdi_recycling.wire import Percepts

from cbdi.beliefs import fact, instance
from cbdi.wire.agent import ActionStatus, ArrestReport, PartialPlan, PlanStep
from cbdi.wire.world import (
    ActionOutcome,
    ItemView,
)
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind

AGENT = Path(__file__).resolve().parents[2] / "domains/recycling/agents/recycler.toml"


def percepts(
    epoch: int,
    litter: list[tuple[str, tuple[int, int]]] = (),  # type: ignore[assignment]
    holding: list[str] = (),
    position: tuple[int, int] = (0, 1),
    free: tuple[tuple[int, int], ...] = ((1, 1),),
) -> Percepts:  # type: ignore[assignment]
    return Percepts(
        agent="robot1",
        epoch=epoch,
        time=float(epoch),
        position=position,
        depth=1,
        free=list(free),
        blocked=[(0, 0)],
        holding=list(holding),
        items=[ItemView(name=n, cell=c) for n, c in litter],
    )


def test_sensing_litter_activates_recycling_and_extends_its_goal() -> None:
    mind = Mind(load_agent(AGENT, "robot1"))
    first = mind.on_percepts(percepts(0, [("pla1", (1, 1))]))
    assert [(e.desire, e.event) for e in first.events] == [
        ("recycle", "added"),
        ("recycle", "activated"),
    ]
    assert [c.kind for c in first.commands] == ["start_search"]
    assert first.commands[0].desire is not None
    assert first.commands[0].desire.goal == (fact("recycled", "pla1"),)
    quiet = mind.on_percepts(percepts(1, [("pla1", (1, 1))]))
    assert quiet.commands == [] and quiet.events == []  # nothing changed: nothing to do
    more = mind.on_percepts(percepts(2, [("pla1", (1, 1)), ("pla2", (0, 2))]))
    assert ("recycle", "boosted") in [(e.desire, e.event) for e in more.events]
    revised = [c for c in more.commands if c.kind == "start_search"]
    assert revised and revised[0].reason == "goal revised"


def test_plans_flow_to_the_executor_and_failures_replan() -> None:
    mind = Mind(load_agent(AGENT, "robot1"))
    mind.on_percepts(percepts(0, [("pla1", (1, 1))]))
    step = PlanStep(
        step_id="a", action="move", args=["robot1", "c_0_1", "c_1_1"], start=0, duration=1
    )
    plan = PartialPlan(agent="robot1", plan_id="p1", baseline="", steps=[step])
    assert [c.kind for c in mind.on_plan(plan).commands] == ["execute"]
    failed = ActionStatus(
        agent="robot1",
        plan_id="p1",
        step_id="a",
        action="move",
        status="failed",
        reason="blocked by person p",
        time=1.0,
    )
    assert [c.kind for c in mind.on_status(failed).commands] == ["start_search"]
    assert (
        mind.on_arrested(
            ArrestReport(agent="robot1", plan_id="p1", last_step="a", time=1, cancelled=[])
        ).commands
        == []
    )


def test_the_goal_is_achieved_when_the_world_says_recycled() -> None:
    mind = Mind(load_agent(AGENT, "robot1"))
    mind.on_percepts(percepts(0, [("pla1", (1, 1))]))
    mind.on_percepts(percepts(3, holding=["pla1"], position=(1, 1)))
    done = ActionOutcome(
        agent="robot1",
        request_id="x",
        action="recycle",
        status="succeeded",
        reason="",
        epoch=9,
        time=9.0,
        item="pla1",
    )
    assert mind.on_outcome(done).beliefs_changed
    out = mind.on_percepts(percepts(10, position=(1, 1)))
    assert ("recycle", "achieved") in [(e.desire, e.event) for e in out.events]
    assert "achieved" in [c.kind for c in out.commands]
    assert mind.intentions.current is None and "recycle" not in mind.desires


def test_a_passed_deadline_drops_the_desire() -> None:
    mind = Mind(load_agent(AGENT, "robot1"))
    mind.on_percepts(percepts(0, [("pla1", (1, 1))]))
    late = mind.on_percepts(percepts(65, [("pla1", (1, 1))]))
    dropped = [e for e in late.events if e.event == "dropped"]
    assert len(dropped) == 1 and "deadline" in dropped[0].reason
    assert "drop" in [c.kind for c in late.commands]


def _executing(mind: Mind) -> None:
    step = PlanStep(step_id="p-1", action="move", args=[], start=1.0, duration=1.0)
    plan = PartialPlan(agent="robot1", plan_id="p", baseline="", steps=[step], complete=False)
    assert "execute" in [c.kind for c in mind.on_plan(plan).commands]


def test_a_running_intention_keeps_its_desire_past_the_deadline_up_to_rtc_deadline() -> None:
    """The deadline is for planning: a robot carrying out its plan is not stopped midway
    (the paper's 64 s recycling deadline used to drop and re-take the desire), but only
    up to `rtc_deadline` (2) times the span: 64 + 64 s."""
    mind = Mind(load_agent(AGENT, "robot1"))
    mind.on_percepts(percepts(0, [("pla1", (1, 1))]))
    _executing(mind)
    kept = mind.on_percepts(percepts(100, [("pla1", (1, 1))]))
    assert not [e for e in kept.events if e.event == "dropped"]
    assert mind.intentions.current is not None and mind.intentions.current.plan_id == "p"
    late = mind.on_percepts(percepts(129, [("pla1", (1, 1))]))
    dropped = [e for e in late.events if e.event == "dropped"]
    assert len(dropped) == 1 and "deadline 128 passed" in dropped[0].reason


def test_a_boost_with_a_new_literal_gives_the_desire_its_span_again() -> None:
    mind = Mind(load_agent(AGENT, "robot1"))
    mind.on_percepts(percepts(0, [("pla1", (1, 1))]))
    assert mind.desires["recycle"].deadline == 64.0
    mind.on_percepts(percepts(30, [("pla1", (1, 1)), ("pla2", (1, 1))]))
    assert mind.desires["recycle"].deadline == 94.0  # pla2 was seen at 30
    mind.on_percepts(percepts(40, [("pla1", (1, 1)), ("pla2", (1, 1))]))
    assert mind.desires["recycle"].deadline == 94.0  # nothing new: no refresh


LITTER = [("pla1", (1, 1))]


def test_a_stalled_wait_makes_the_robot_step_aside_then_resume() -> None:
    mind = Mind(load_agent(AGENT, "robot1"))
    mind.on_percepts(percepts(0, LITTER))
    mind.beliefs = mind.beliefs.adding(
        [instance("c_0_2", "cell"), fact("near", "c_0_1", "c_0_2"), fact("free", "c_0_2")]
    )
    waiting = mind.on_search_failed("a person on the way", blocked=True)
    assert [(e.desire, e.event) for e in waiting.events] == [("recycle", "waiting")]
    events = []
    for epoch in range(1, 12):  # the person waits for the robot: nothing changes
        events += [
            (epoch, e.desire, e.event)
            for e in mind.on_percepts(percepts(epoch, LITTER, free=((1, 1), (0, 2)))).events
        ]
    assert (9, "step_aside", "added") in events and (9, "step_aside", "activated") in events
    assert not [e for e in events if e[1] == "recycle" and e[2] == "dropped"]
    assert mind.desires["step_aside"].goal == (fact("in", "robot1", "c_0_2"),)
    # Stepped aside: the recycling desire is taken up again, with a fresh search.
    out = mind.on_percepts(percepts(12, LITTER, position=(0, 2)))
    assert ("recycle", "activated") in [(e.desire, e.event) for e in out.events]
    assert [c.kind for c in out.commands][-1] == "start_search"
    assert not [f for f in mind.beliefs.facts if f[0] == "stalled"]


def test_a_requested_desire_is_pursued_and_a_withdrawn_one_dropped() -> None:
    from cbdi.wire.agent import AgentRequest
    from cbdi_scheduler.requests import serve_request

    mind = Mind(load_agent(AGENT, "robot1"))
    mind.on_percepts(percepts(0))
    ask = AgentRequest(
        from_agent="operator",
        group="recyclers",
        op="add_desire",
        desire="visit",
        goal=["(in robot1 c_3_3)"],
        priority=0.9,
    )
    assert serve_request(mind, ask).accepted
    taken = mind.on_percepts(percepts(1))
    assert [(e.desire, e.event) for e in taken.events] == [
        ("visit", "added"),
        ("visit", "activated"),
    ]
    assert [c.kind for c in taken.commands] == ["start_search"]
    remove = AgentRequest(from_agent="operator", group="recyclers", op="del_desire", desire="visit")
    assert serve_request(mind, remove).accepted
    gone = mind.on_percepts(percepts(2))
    assert [(e.desire, e.event, e.reason) for e in gone.events] == [
        ("visit", "dropped", "removed by operator")
    ]
    assert "drop" in [c.kind for c in gone.commands]
    assert "visit" not in mind.desires and mind.intentions.current is None


def test_a_safe_stop_keeps_the_intention_and_its_deadline_until_resumed() -> None:
    from cbdi.wire.agent import AgentRequest
    from cbdi_scheduler.requests import serve_request

    def ask(op: str) -> AgentRequest:
        return AgentRequest(from_agent="operator", group="operator", op=op)  # type: ignore[arg-type]

    mind = Mind(load_agent(AGENT, "robot1"))
    mind.on_percepts(percepts(0, [("pla1", (1, 1))]))
    steps = [
        PlanStep(step_id=i, action="move", args=["robot1", "c_0_1", "c_1_1"], start=t, duration=1)
        for i, t in (("a", 0), ("b", 1))
    ]
    mind.on_plan(PartialPlan(agent="robot1", plan_id="p1", baseline="", steps=steps))
    running = ActionStatus(
        agent="robot1",
        plan_id="p1",
        step_id="a",
        action="move",
        status="running",
        reason="",
        time=0,
    )
    mind.on_status(running)
    assert "not halted" in serve_request(mind, ask("resume")).reason
    assert serve_request(mind, ask("halt")).accepted
    stop = mind.on_percepts(percepts(1, [("pla1", (1, 1))]))
    assert [(c.kind, c.after_step) for c in stop.commands] == [
        ("cancel_search", ""),
        ("arrest", "a"),
    ]
    assert [(e.desire, e.event) for e in stop.events] == [("recycle", "halted")]
    late = PartialPlan(agent="robot1", plan_id="p2", baseline="p1", steps=steps)
    assert mind.on_plan(late).commands == []  # nothing new starts
    report = ArrestReport(agent="robot1", plan_id="p1", last_step="a", time=1.0, cancelled=["b"])
    assert mind.on_arrested(report).commands == []
    held = mind.on_percepts(percepts(100, [("pla1", (1, 1))]))  # past the deadline (64)
    assert not [e for e in held.events if e.event == "dropped"] and "recycle" in mind.desires
    assert serve_request(mind, ask("resume")).accepted
    go = mind.on_percepts(percepts(101, [("pla1", (1, 1))]))
    assert [(c.kind, c.reason) for c in go.commands] == [("start_search", "resumed")]
    assert [(e.desire, e.event) for e in go.events] == [("recycle", "resumed")]
    assert mind.desires["recycle"].deadline == 64 + 100  # it waited the 100 s stopped
    assert mind.intentions.current is not None and not mind.intentions.halted


def test_an_idle_robot_on_its_way_home_past_a_bin_is_not_turned_back() -> None:
    """make_way (next to a bin) used to outrank go_home: a way home along a bin sent the
    robot back, then home again, for ever (seen on campus-30x30 with 8 robots)."""
    mind = Mind(load_agent(AGENT, "robot1"))
    cells = [f"c_{x}_0" for x in range(6)]
    mind.beliefs = mind.beliefs.adding(
        [
            instance("bin1", "bin"),
            fact("bin_pose", "bin1", "c_0_0"),
            fact("home", "robot1", "c_5_0"),
        ]
        + [fact("near", a, b) for a, b in pairwise(cells)]
        + [fact("near", b, a) for a, b in pairwise(cells)]
    )
    seen = Percepts(
        agent="robot1",
        epoch=0,
        time=0.0,
        position=(1, 0),
        depth=1,
        free=[(2, 0), (3, 0), (4, 0), (5, 0)],  # all sensed: nothing to explore
        blocked=[(0, 0)],
        holding=[],
        items=[],
    )
    out = mind.on_percepts(seen)
    assert {"make_way", "go_home"} <= set(mind.desires)
    assert [(e.desire, e.event) for e in out.events if e.event == "activated"] == [
        ("go_home", "activated")
    ]


def test_a_rule_binds_the_precondition_of_the_desire_it_adds() -> None:
    """make_way's precondition `(in {self} {c})` was kept unbound: any cell matched, so
    the desire stayed selectable after the robot left and robots turned back to it."""
    mind = Mind(load_agent(AGENT, "robot1"))
    cells = ["c_0_0", "c_0_1", "c_0_2"]
    mind.beliefs = mind.beliefs.adding(
        [
            instance("bin1", "bin"),
            fact("bin_pose", "bin1", "c_0_0"),
            fact("home", "robot1", "c_0_1"),
        ]
        + [fact("near", a, b) for a, b in pairwise(cells)]
        + [fact("near", b, a) for a, b in pairwise(cells)]
    )
    mind.on_percepts(percepts(0, position=(0, 1), free=((0, 2),)))
    make_way = mind.desires["make_way"]
    (clause,) = make_way.precondition
    assert [str(lit.belief) for lit in clause] == ["(in robot1 c_0_1)"]
    away = mind.on_percepts(percepts(1, position=(0, 2), free=((0, 1),)))
    assert ("make_way", "achieved") in [(e.desire, e.event) for e in away.events]


def test_a_failed_replan_is_retried_when_a_sensor_or_an_outcome_changes_the_beliefs() -> None:
    """Issue 31's stall: a step refused before sensing caught up, the replan from the
    stale beliefs failed, and only the world's percepts could retry it. Any change of
    the beliefs between cycles retries it now, and the wait says why meanwhile."""
    from cbdi.wire.agent import AgentRequest
    from cbdi_scheduler.requests import serve_request

    mind = Mind(load_agent(AGENT, "robot1"))
    mind.on_percepts(percepts(0, [("pla1", (1, 1))]))
    step = PlanStep(
        step_id="a", action="move", args=["robot1", "c_0_1", "c_1_1"], start=0, duration=1
    )
    mind.on_plan(PartialPlan(agent="robot1", plan_id="p1", baseline="", steps=[step]))
    refused = ActionStatus(
        agent="robot1",
        plan_id="p1",
        step_id="a",
        action="move",
        status="refused",
        reason="at start condition (in robot1 c_0_1) does not hold",
        time=1.0,
    )
    assert [c.kind for c in mind.on_status(refused).commands] == ["start_search"]
    failed = mind.on_search_failed("no plan from the beliefs")
    assert [(e.desire, e.event) for e in failed.events] == [("recycle", "waiting")]
    assert "no plan from the beliefs" in failed.events[0].reason
    same = [("pla1", (1, 1))]
    assert [c.kind for c in mind.on_percepts(percepts(1, same)).commands] == []
    # A sensor's reading, between two cycles the world's percepts do not change.
    sensed = AgentRequest(
        from_agent="sensor", group="sensors", op="del_belief", belief="(map_loaded)"
    )
    assert serve_request(mind, sensed).accepted
    retried = mind.on_percepts(percepts(2, same)).commands
    assert [c.kind for c in retried] == ["start_search"]
    assert "no plan from the beliefs" in retried[0].reason
    # An outcome's change counts the same way.
    mind.on_search_failed("no plan from the beliefs")
    assert [c.kind for c in mind.on_percepts(percepts(3, same)).commands] == []
    recycled = ActionOutcome(
        agent="robot1",
        request_id="r1",
        action="recycle",
        status="succeeded",
        reason="",
        epoch=3,
        time=3.5,
        item="pla2",  # what no percept shows: only the outcome tells
    )
    assert mind.on_outcome(recycled).beliefs_changed
    retried = mind.on_percepts(percepts(4, same)).commands
    assert [c.kind for c in retried] == ["start_search"]
    assert [c.kind for c in mind.on_percepts(percepts(5, same)).commands] == []  # once


def test_a_search_that_fails_after_a_change_under_it_is_retried_with_no_further_change() -> None:
    """Real time: the sensor's reading came while the search ran (from the beliefs
    before it), and a cycle took it in before the search failed. Waiting for yet another
    change could wait until the deadline; the next cycle searches again."""
    from cbdi.wire.agent import AgentRequest
    from cbdi_scheduler.requests import serve_request

    mind = Mind(load_agent(AGENT, "robot1"))
    same = [("pla1", (1, 1))]
    assert [c.kind for c in mind.on_percepts(percepts(0, same)).commands] == ["start_search"]
    sensed = AgentRequest(
        from_agent="sensor", group="sensors", op="add_belief", belief="(recycled pla9)"
    )
    assert serve_request(mind, sensed).accepted
    assert [c.kind for c in mind.on_percepts(percepts(1, same)).commands] == []  # searching
    failed = mind.on_search_failed("no plan from the beliefs")
    assert "at the next cycle" in failed.events[0].reason
    retried = mind.on_percepts(percepts(2, same)).commands
    assert [c.kind for c in retried] == ["start_search"]
    mind.on_search_failed("no plan from the beliefs")  # from the beliefs of now
    assert [c.kind for c in mind.on_percepts(percepts(3, same)).commands] == []
