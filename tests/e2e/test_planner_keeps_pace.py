"""A planner searching flat out on campus-30x30 keeps its event loop free.

The planner service runs as its own process over real Zenoh with heartbeats every 20
ms. It plans the 30x30 campus problem (24 items) in rounds back to back, while this
test plays scheduler and executor: the plan's first step runs, and every 0.2 s new
beliefs arrive with a person on a cell the plan is about to enter, so the planner
forecasts, repairs and searches again, all the time. Meanwhile it asks the planner
something every 0.25 s over the bus (a malformed request, which the service answers on
its error stream) and times the answer.

What must hold throughout: the loop is never held by the planner's own code for 100 ms
(`Heartbeat.held`, the CPU the loop's thread ran between two turns of its marker: the
same on a loaded machine as on an idle one), the heartbeats keep coming and every
question is answered. The wall-clock figures (heartbeat gaps, answer times) are
printed; a loaded machine stretches them, so only a bound the watchdog cares about (3
s) is asserted on them.
"""

from __future__ import annotations

import asyncio
import itertools
import re
import statistics
import time
from pathlib import Path

import pytest

from cbdi import keys
from cbdi.beliefs import BeliefSet, BeliefsSender
from cbdi.bus import Bus, BusConfig, LogSink, messages, open_bus, publish
from cbdi.wire.agent import ActionStatus, PartialPlan
from cbdi.wire.common import ErrorReport, Heartbeat
from cbdi.wire.planner import SearchRequest
from cbdi_planner.agent.problem import beliefs_from_problem
from cbdi_planner.pddl import parse_domain, parse_problem
from tests_support import REPO, wait_for

pytestmark = pytest.mark.e2e

DOMAIN = REPO / "domains/recycling/pddl/domain.pddl"
PROBLEM = REPO / "domains/recycling/problems/campus-30x30.pddl"
AGENT_FILE = f"""
domain = "{DOMAIN}"
[planning]
mode = "online"
round_interval = 0.1
expansions_per_round = 200
plan_size_limit = 8
min_commit_steps = 1
forecast_horizon = 3
improve_expansions = 3000
"""
BEAT = 0.02  # s between heartbeats
HOLD = 0.1  # s: the loop may never be held longer by the planner's code
WATCH = 12.0  # s of searching watched


async def test_a_planner_searching_flat_out_on_campus_keeps_its_loop_free(
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
        env={"CBDI_CONNECT": router, "CBDI_HEARTBEAT": str(BEAT)},
    )
    wait_for(lambda: "event=ready" in planner.output(), what="planner ready")
    domain = parse_domain(DOMAIN.read_text(), str(DOMAIN))
    believed = beliefs_from_problem(parse_problem(PROBLEM.read_text(), domain))
    bus = await open_bus(BusConfig(connect=(router,)))
    sink = LogSink()
    beats: list[tuple[float, Heartbeat]] = []
    answers: list[float] = []
    asked: dict[int, float] = {}
    plans: list[PartialPlan] = []
    sender = BeliefsSender("robot1")  # changes of beliefs, as the scheduler sends them
    try:
        heartbeats = messages(bus, keys.heartbeat("robot1/planner"), Heartbeat, sink)
        errors = messages(bus, keys.errors("robot1/planner"), ErrorReport, sink)
        plan_stream = messages(bus, keys.planner_plans("robot1"), PartialPlan, sink)

        async def hear() -> None:
            async for _, beat in heartbeats:
                beats.append((time.monotonic(), beat))

        async def answered() -> None:
            async for _, report in errors:
                found = re.search(r"question-(\d+)", report.message)
                if found is not None:
                    answers.append(time.monotonic() - asked.pop(int(found.group(1))))

        async def take_plans() -> None:
            async for _, plan in plan_stream:
                plans.append(plan)

        tasks = [asyncio.create_task(f()) for f in (hear, answered, take_plans)]
        await asyncio.sleep(0.5)
        watched_from = time.monotonic()  # reading, grounding and the first rounds too
        request = SearchRequest(
            agent="robot1", request_id="s1", kind="start", problem=PROBLEM.read_text()
        )
        await publish(bus, keys.planner_requests("robot1"), request, block=True)
        await asyncio.wait_for(_until(lambda: bool(plans)), 60)
        first = plans[0].steps[0]
        running = ActionStatus(
            agent="robot1",
            plan_id=plans[0].plan_id,
            step_id=first.step_id,
            action=first.action,
            status="running",
            reason="",
            time=first.start,
        )
        await publish(bus, keys.executor_status("robot1"), running, block=True)
        for tick in range(int(WATCH / 0.05)):
            now = time.monotonic()
            if tick % 4 == 0:  # a person ahead of the newest plan: forecast, repair
                await _person_ahead(bus, sender, believed, plans[-1], tick, first.start + 0.5)
            if tick % 5 == 0:
                asked[tick] = now
                await _ask(bus, tick)
            await asyncio.sleep(0.05)
        await asyncio.sleep(1.0)  # the last answers
        for task in tasks:
            task.cancel()
    finally:
        await bus.close()
    assert planner.alive(), planner.output()[-3000:]

    watched = [(at, b) for at, b in beats if at >= watched_from]
    gaps = [b - a for (a, _), (b, _) in itertools.pairwise(watched)]
    held = [b.held for _, b in watched]
    late = [b.late for _, b in watched]
    print(
        f"\nheartbeats {len(watched)} in {watched[-1][0] - watched_from:.0f} s: gap median "
        f"{statistics.median(gaps) * 1000:.1f} ms max {max(gaps) * 1000:.1f} ms; loop held "
        f"median {statistics.median(held) * 1000:.1f} ms max {max(held) * 1000:.1f} ms; "
        f"marker late max {max(late) * 1000:.1f} ms; answers {len(answers)}/"
        f"{len(answers) + len(asked)}: median {statistics.median(answers) * 1000:.1f} ms "
        f"max {max(answers) * 1000:.1f} ms; plans {len(plans)}"
    )
    assert len(plans) >= 3, "the planner kept planning (repairs)"
    assert max(held) < HOLD, sorted(held)[-5:]
    assert not asked, f"questions never answered: {sorted(asked)}"
    assert max(gaps) < 3.0 and max(answers) < 3.0  # a loaded machine stretches these


async def _until(condition: object) -> None:
    while not condition():  # type: ignore[operator]
        await asyncio.sleep(0.02)


async def _ask(bus: Bus, n: int) -> None:
    """A request the planner must refuse at once: an unknown predicate in its goal."""
    bad = SearchRequest(
        agent="robot1",
        request_id=f"question-{n}",
        kind="start",
        goal=[["no_such_predicate", f"question-{n}"]],
    )
    await publish(bus, keys.planner_requests("robot1"), bad, block=True)


async def _person_ahead(
    bus: Bus, sender: BeliefsSender, believed: BeliefSet, plan: PartialPlan, tick: int, now: float
) -> None:
    cells = [s.args[2] for s in plan.steps if s.action == "move"]
    if not cells:
        return
    cell = cells[min(len(cells) - 1, 1 + tick % 3)]
    seen = BeliefSet(believed.instances, believed.facts - {("free", cell)}, believed.fluents)
    await publish(bus, keys.scheduler_beliefs("robot1"), sender.update(seen, now), block=True)
