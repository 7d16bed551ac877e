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
