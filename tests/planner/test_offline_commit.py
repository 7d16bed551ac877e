"""The offline planner plans from the state the running steps leave (the committed state).

Found on campus-30x30 with the compiled core's planning speed: an offline search asked
while a plan executed (a revised goal once an item was seen) planned from the beliefs of
that moment, the robot in the middle of a move; by the time its plan came the move had
ended one cell on, and the plan's first move was refused ("at start condition (in
robot1 c_7_2) does not hold"), four times in a row once, and the desire was dropped.
"""

from __future__ import annotations

import asyncio
import dataclasses

from msgspec.structs import replace
from test_bad_input import AGENT_FILE, alone
from test_online import DOMAIN, beliefs

from cbdi import keys
from cbdi.agentfile import read_agent_file
from cbdi.beliefs import to_wire
from cbdi.bus import LogSink, messages
from cbdi.runtime.together import TogetherService
from cbdi.wire import encode
from cbdi.wire.agent import ActionStatus, PartialPlan, PlanStep
from cbdi.wire.planner import SearchRequest, SearchStatus
from cbdi_planner.agent.offline import Committed, Execution
from cbdi_planner.agent.service import PlannerSettings, planner_main

GOAL = [["recycled", "p1"]]


def step(n: int, action: str, *args: str, start: float) -> PlanStep:
    return PlanStep(step_id=f"p-{n}", action=action, args=list(args), start=start, duration=1.0)


def execution() -> Execution:
    """robot1 sent from c_1_0 to c_3_0, one cell a second from t=5."""
    e = Execution()
    e.follow(
        0,
        [
            step(1, "move", "robot1", "c_1_0", "c_2_0", start=5.0),
            step(2, "move", "robot1", "c_2_0", "c_3_0", start=6.0),
        ],
    )
    return e


def status(n: int, what: str) -> ActionStatus:
    return ActionStatus(
        agent="robot1",
        plan_id="p",
        step_id=f"p-{n}",
        action="move",
        status=what,
        reason="",
        time=5.0,
    )


def robot_in(problem: object) -> list[tuple[str, ...]]:
    return [a.args for a in problem.init if a.predicate == "in"]  # type: ignore[attr-defined]


def test_nothing_running_plans_from_the_beliefs() -> None:
    c = execution().commit(DOMAIN, beliefs(), GOAL)
    assert (c.count, c.after) == (0, "")
    assert robot_in(c.problem) == [("robot1", "c_1_0")]


def test_a_running_step_is_committed_and_the_plan_follows_it() -> None:
    e = execution()
    e.on_status(status(1, "running"))
    c = e.commit(DOMAIN, beliefs(), GOAL)
    assert (c.count, c.after, c.ends) == (1, "p-1", 6.0)
    assert robot_in(c.problem) == [("robot1", "c_2_0")]
    facts = {(a.predicate, *a.args) for a in c.problem.init}
    assert ("free", "c_1_0") in facts and ("free", "c_2_0") not in facts
    assert ("near", "c_1_0", "c_2_0") in facts  # what no action changes stays


def test_a_running_step_that_cannot_be_simulated_leaves_the_beliefs_as_they_are() -> None:
    e = execution()
    e.on_status(status(1, "running"))
    # c_2_0 is believed taken (a person): the move cannot be simulated from here.
    c = e.commit(DOMAIN, beliefs(blocked=("c_2_0",)), GOAL)
    assert (c.count, c.after) == (0, "")
    assert robot_in(c.problem) == [("robot1", "c_1_0")]


def test_finished_steps_stay_behind_the_commitment() -> None:
    e = execution()
    e.on_status(status(1, "succeeded"))
    e.on_status(status(2, "running"))
    c = e.commit(DOMAIN, beliefs(robot="c_2_0"), GOAL)
    assert (c.count, c.after, c.ends) == (2, "p-2", 7.0)
    assert robot_in(c.problem) == [("robot1", "c_3_0")]


async def test_a_revised_search_follows_the_running_step() -> None:
    """The service: a plan goes out, its first step runs, the goal is revised; the new
    plan follows that step (applies_after), from where it ends, when it ends."""
    settings = PlannerSettings(agent="robot1", agent_file=AGENT_FILE, planning="offline")
    agent = read_agent_file(AGENT_FILE, "robot1")
    shell = TogetherService("robot1/planner", settings, planner_main(settings, DOMAIN, agent))
    async with alone(shell) as (bus, _):
        statuses = messages(bus, keys.planner_status("robot1"), SearchStatus, LogSink())
        plans = messages(bus, keys.planner_plans("robot1"), PartialPlan, LogSink())
        await bus.publish(
            keys.scheduler_beliefs("robot1"),
            encode(replace(to_wire(beliefs(), "robot1", 0.0), seq=1)),
        )
        requests = keys.planner_requests("robot1")
        first = SearchRequest(agent="robot1", request_id="s1", kind="start", goal=GOAL, beliefs=1)
        await bus.publish(requests, encode(first))
        async with asyncio.timeout(30):
            _, plan = await anext(plans)
        assert plan.applies_after == ""
        one = plan.steps[0]
        assert (one.action, one.args) == ("move", ["robot1", "c_1_0", "c_2_0"])
        running = ActionStatus(
            agent="robot1",
            plan_id=plan.plan_id,
            step_id=one.step_id,
            action="move",
            status="running",
            reason="",
            time=one.start,
        )
        await bus.publish(keys.executor_status("robot1"), encode(running))
        # One subscription takes every input in order: the status is in before the revision.
        revise = SearchRequest(
            agent="robot1", request_id="s1", kind="revise", goal=[*GOAL, ["recycled", "p2"]]
        )
        await bus.publish(requests, encode(revise))
        async with asyncio.timeout(30):
            _, again = await anext(plans)
            while (await anext(statuses))[1].status != "done":
                pass
        assert again.applies_after == one.step_id
        assert again.steps[0].start >= one.start + one.duration
        first_move = again.steps[0]
        assert first_move.action == "move" and first_move.args[1] == "c_2_0", first_move


def test_a_running_pickup_the_beliefs_show_ended_is_committed_as_ended() -> None:
    """The executor's `running` can come after the percepts that show the step ended
    (the item in hand, gone from the floor: the pickup no longer grounds). Given the
    beliefs' time, past its end, the plan follows it from the beliefs as they are."""
    e = Execution()
    e.follow(0, [PlanStep(step_id="p-1", action="litter_pickup", args=["robot1", "p2", "c_3_0"],
                          start=5.0, duration=3.0)])  # fmt: skip
    e.on_status(replace(status(1, "running"), action="litter_pickup"))
    b = beliefs(robot="c_3_0")
    ended = dataclasses.replace(
        b,
        facts=(b.facts - {("litter_pose", "p2", "c_3_0")}) | {("holding", "robot1", "p2")},
        fluents={**b.fluents, ("loaded_amount", "robot1"): 1.0},
    )
    c = e.commit(DOMAIN, ended, GOAL, 8.0)
    assert (c.count, c.after, c.ends) == (1, "p-1", 8.0)
    (value,) = [v for h, v in c.problem.init_numeric.items() if h.name == "loaded_amount"]
    assert value == 1.0  # not counted again
    # Before its planned end, with its end's effects shown (it ended early): the same.
    c = e.commit(DOMAIN, ended, GOAL, 7.0)
    assert (c.count, _loaded(c)) == (1, 1.0)
    # Mid-way (the item off the floor, not yet in hand; the task still reaches the
    # pickup from the facts it started from): its end applies, once.
    mid = dataclasses.replace(b, facts=b.facts - {("litter_pose", "p2", "c_3_0")})
    c = e.commit(DOMAIN, mid, GOAL, 7.0)
    assert (c.count, _loaded(c)) == (1, 1.0)
    assert ("holding", "robot1", "p2") in {(a.predicate, *a.args) for a in c.problem.init}


def _loaded(c: Committed) -> float:
    (value,) = [v for h, v in c.problem.init_numeric.items() if h.name == "loaded_amount"]
    return value
