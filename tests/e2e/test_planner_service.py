"""The planner service alone, over real Zenoh, fed by a scripted executor (this test).

It plans the paper's 7x7 problem in rounds: partial plans arrive before the plan is
complete and, put together, form a plan an independent validator (kairos) accepts. The
test then plays executor: the first step runs, and a person stands on a cell the plan is
about to enter; the planner forecasts the failure after the committed step and publishes
a repair that continues after it and avoids the cell. Bad input on every input key is
answered on the service's error stream, and the service keeps serving.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path
from typing import TypeVar

import pytest
from planning import validate

from cbdi import keys
from cbdi.beliefs import BeliefSet, to_wire
from cbdi.bus import Bus, BusConfig, LogSink, messages, open_bus, publish
from cbdi.wire.agent import ActionStatus, PartialPlan
from cbdi.wire.base import Message
from cbdi.wire.common import ErrorReport
from cbdi.wire.planner import ForecastReport, SearchRequest, SearchRound, SearchStatus
from cbdi_planner.agent.problem import beliefs_from_problem
from cbdi_planner.pddl import parse_domain, parse_problem
from tests_support import REPO, wait_for

pytestmark = pytest.mark.e2e

DOMAIN = REPO / "domains/recycling/pddl/domain.pddl"
PROBLEM = REPO / "domains/recycling/problems/paper-7x7.pddl"
AGENT_FILE = f"""
domain = "{DOMAIN}"
[planning]
mode = "online"
round_interval = 0.1
expansions_per_round = 100
plan_size_limit = 6
min_commit_steps = 1
forecast_horizon = 3
"""
M = TypeVar("M", bound=Message)


async def next_of(stream: AsyncIterator[tuple[str, M]], timeout: float = 20.0) -> M:
    _, msg = await asyncio.wait_for(anext(stream), timeout)
    return msg


def status(plan_id: str, step_id: str, what: str, time: float) -> ActionStatus:
    return ActionStatus(
        agent="robot1",
        plan_id=plan_id,
        step_id=step_id,
        action="",
        status=what,
        reason="",
        time=time,
    )


async def send_garbage(bus: Bus) -> None:
    """Bad input of every kind the planner takes in."""
    await bus.publish(keys.planner_requests("robot1"), b"\xc1 not msgpack", block=True)
    broken = PROBLEM.read_text().replace("(:init", "(:init (in robot1", 1)
    bad = SearchRequest(agent="robot1", request_id="bad-1", kind="start", problem=broken)
    await publish(bus, keys.planner_requests("robot1"), bad, block=True)
    unknown_goal = SearchRequest(
        agent="robot1", request_id="bad-2", kind="start", goal=[["shiny", "x"]], problem=""
    )
    await publish(bus, keys.planner_requests("robot1"), unknown_goal, block=True)
    intruder = SearchRequest(agent="robot9", request_id="bad-3", kind="start")
    await publish(bus, keys.planner_requests("robot1"), intruder, block=True)
    await publish(
        bus,
        keys.executor_status("robot1"),
        status("nobody-plan", "nobody-1", "running", 0),
        block=True,
    )


async def test_planner_service_plans_in_rounds_and_repairs_before_failure(
    router: str, spawn: object, tmp_path: Path
) -> None:
    agent_file = tmp_path / "agent.toml"
    agent_file.write_text(AGENT_FILE)
    planner = spawn(  # type: ignore[operator]
        "planner",
        "cbdi-planner",
        "serve",
        "--agent",
        "robot1",
        "--agent-file",
        str(agent_file),
        "--time-grid",
        "0.001",
        "--no-improve",
        env={"CBDI_CONNECT": router},
    )
    wait_for(lambda: "event=ready" in planner.output(), what="planner ready")
    bus = await open_bus(BusConfig(connect=(router,)))
    sink = LogSink()
    try:
        plans = messages(bus, keys.planner_plans("robot1"), PartialPlan, sink)
        statuses = messages(bus, keys.planner_status("robot1"), SearchStatus, sink)
        rounds = messages(bus, keys.planner_rounds("robot1"), SearchRound, sink)
        forecasts = messages(bus, keys.planner_forecasts("robot1"), ForecastReport, sink)
        errors = messages(bus, keys.errors("robot1/planner"), ErrorReport, sink)
        await asyncio.sleep(0.5)

        await send_garbage(bus)
        codes = [(await next_of(errors)).code for _ in range(5)]
        assert sorted(codes) == sorted(
            ["WireError", "bad_request", "bad_request", "unknown_agent", "unknown_plan"]
        ), codes
        failed = [await next_of(statuses) for _ in range(2)]
        assert [s.status for s in failed] == ["failed", "failed"]
        assert "bad-1:" in failed[0].reason and "no predicate 'shiny'" in failed[1].reason

        # -- plan the paper's problem, carried in the request --------------------------
        request = SearchRequest(
            agent="robot1", request_id="s1", kind="start", problem=PROBLEM.read_text()
        )
        await publish(bus, keys.planner_requests("robot1"), request, block=True)
        assert (await next_of(statuses)).status == "searching"
        parts: list[PartialPlan] = []
        while not parts or not parts[-1].complete:
            parts.append(await next_of(plans))
        assert (await next_of(statuses)).status == "done"
        assert len(parts) >= 2 and not parts[0].complete  # execution could start early
        plan_id = parts[0].plan_id
        assert all(p.plan_id == plan_id for p in parts)
        assert parts[0].baseline == "" and all(p.baseline == plan_id for p in parts[1:])
        assert (await next_of(rounds)).plan_id == plan_id

        steps = [s for p in parts for s in p.steps]
        origin = min(s.start for s in steps)
        lines = [
            f"{s.start - origin:.3f}: ({' '.join([s.action, *s.args])}) [{s.duration:.3f}]"
            for s in steps
        ]
        plan_file = tmp_path / "concatenated.plan"
        plan_file.write_text("\n".join(lines) + "\n")
        valid, out = validate(DOMAIN, PROBLEM, plan_file)
        assert valid, out

        # -- play executor: step 1 runs, a person steps onto a cell the plan enters next --
        first = steps[0]
        ahead = next(s for s in steps[1:4] if s.action == "move" and s.args[2] != first.args[-1])
        person_cell = ahead.args[2]
        await publish(
            bus,
            keys.executor_status("robot1"),
            status(plan_id, first.step_id, "running", first.start),
            block=True,
        )
        domain = parse_domain(DOMAIN.read_text(), str(DOMAIN))
        believed = beliefs_from_problem(parse_problem(PROBLEM.read_text(), domain))
        blocked = BeliefSet(
            believed.instances, believed.facts - {("free", person_cell)}, believed.fluents
        )
        await publish(
            bus,
            keys.scheduler_beliefs("robot1"),
            to_wire(blocked, "robot1", first.start + 0.5),
            block=True,
        )
        report = await next_of(forecasts)
        assert report.kind == "fails_after_committed", report
        assert report.failed_step == ahead.step_id and report.committed == first.step_id
        repair = await next_of(plans)
        assert repair.plan_id != plan_id
        assert repair.baseline == first.step_id and repair.applies_after == first.step_id
        assert all(not (s.action == "move" and s.args[2] == person_cell) for s in repair.steps)
    finally:
        await bus.close()
    assert planner.alive()
    assert "event=bad_input" in planner.output()
