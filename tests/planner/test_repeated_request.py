"""The offline planner takes a search request sent again as the one it is on.

The scheduler sends its search again when it sees its planner appear (a request sent
before the planner subscribed would be lost). When that liveliness event reaches it is
up to the machine: in a lockstep run it could come after the search began, and a
restarted search made the run depend on the load (1 run in 10 of `paper-7x7-k2-bdi
--mode offline` differed). A repeat changes nothing; a new request, or one whose search
failed, is searched.
"""

from __future__ import annotations

import asyncio

from test_bad_input import AGENT_FILE, alone
from test_online import CORRIDOR

from cbdi import keys
from cbdi.agentfile import read_agent_file
from cbdi.bus import LogSink, messages
from cbdi.runtime.together import TogetherService
from cbdi.wire import encode
from cbdi.wire.agent import PartialPlan
from cbdi.wire.planner import SearchRequest, SearchStatus
from cbdi_planner.agent.problem import goal_of
from cbdi_planner.agent.service import PlannerSettings, planner_main
from cbdi_planner.pddl import parse_domain, parse_problem


async def test_a_repeated_start_is_not_searched_again() -> None:
    settings = PlannerSettings(agent="robot1", agent_file=AGENT_FILE, planning="offline")
    agent = read_agent_file(AGENT_FILE, "robot1")
    domain = parse_domain(agent.domain.read_text(encoding="utf-8"), str(agent.domain))
    goal = goal_of(parse_problem(CORRIDOR, domain))
    shell = TogetherService("robot1/planner", settings, planner_main(settings, domain, agent))
    async with alone(shell) as (bus, _):
        statuses = messages(bus, keys.planner_status("robot1"), SearchStatus, LogSink())
        plans = messages(bus, keys.planner_plans("robot1"), PartialPlan, LogSink())
        key = keys.planner_requests("robot1")

        async def until(request_id: str, status: str) -> list[tuple[str, str]]:
            seen = []
            async with asyncio.timeout(30):
                while True:
                    _, s = await anext(statuses)
                    seen.append((s.request_id, s.status))
                    if (s.request_id, s.status) == (request_id, status):
                        return seen

        first = SearchRequest(agent="robot1", request_id="s1", kind="start", problem=CORRIDOR)
        await bus.publish(key, encode(first))
        assert await until("s1", "done") == [("s1", "searching"), ("s1", "done")]
        again = SearchRequest(agent="robot1", request_id="s1", kind="start", goal=goal)
        await bus.publish(key, encode(again))
        other = SearchRequest(agent="robot1", request_id="s2", kind="start", goal=goal)
        await bus.publish(key, encode(other))
        # Nothing answers the repeat: the next statuses are the new request's.
        assert await until("s2", "done") == [("s2", "searching"), ("s2", "done")]
        async with asyncio.timeout(10):
            ids = [(await anext(plans))[1].plan_id for _ in range(2)]
        assert len(set(ids)) == 2  # one plan per request searched


async def test_a_search_that_overtook_its_beliefs_waits_for_them() -> None:
    """In real time the scheduler's search and the beliefs it was made from travel on two
    keys, and the search may come first (seen under load in the tutorial: the planner
    searched from the beliefs before, where the goal could never hold, and failed for
    good). A request names the beliefs it was asked from: the planner waits for them."""
    from msgspec.structs import replace as replaced
    from test_online import beliefs

    from cbdi.beliefs import BeliefSet, to_wire

    settings = PlannerSettings(agent="robot1", agent_file=AGENT_FILE)  # online
    agent = read_agent_file(AGENT_FILE, "robot1")
    domain = parse_domain(agent.domain.read_text(encoding="utf-8"), str(agent.domain))
    known = beliefs()
    # Before: p1 not seen yet (the goal can never hold from these).
    unseen = BeliefSet(
        instances={n: t for n, t in known.instances.items() if n != "p1"},
        facts=frozenset(f for f in known.facts if "p1" not in f),
        fluents=known.fluents,
    )
    shell = TogetherService("robot1/planner", settings, planner_main(settings, domain, agent))
    async with alone(shell) as (bus, _):
        statuses = messages(bus, keys.planner_status("robot1"), SearchStatus, LogSink())
        beliefs_key = keys.scheduler_beliefs("robot1")
        await bus.publish(beliefs_key, encode(replaced(to_wire(unseen, "robot1", 0.0), seq=1)))
        search = SearchRequest(
            agent="robot1", request_id="s1", kind="start", goal=[["recycled", "p1"]], beliefs=2
        )
        await bus.publish(keys.planner_requests("robot1"), encode(search))
        await asyncio.sleep(0.2)  # the planner has the request: it must not search yet
        await bus.publish(beliefs_key, encode(replaced(to_wire(known, "robot1", 1.0), seq=2)))
        async with asyncio.timeout(30):
            seen = [(await anext(statuses))[1] for _ in range(2)]
        assert [(s.request_id, s.status) for s in seen] == [("s1", "searching"), ("s1", "done")], [
            (s.status, s.reason) for s in seen
        ]
