"""Function values and events from sensors (issue 31): what the scheduler takes of them,
what it refuses and why, and what the planner and the rules then see. The rover of
`tests/scheduler/rover`: a battery function and a `bumped` event its rule turns into an
alarm."""

from __future__ import annotations

import asyncio
import io
import math
from pathlib import Path

import pytest

from cbdi import keys
from cbdi.beliefs import BeliefsReceiver, fact, fluent
from cbdi.bus import LogSink, MemoryNetwork, messages, request
from cbdi.errors import RequestFailedError
from cbdi.runtime.log import Log
from cbdi.runtime.together import Together, TogetherService
from cbdi.sensor import Prototype, run_sensor
from cbdi.wire import encode
from cbdi.wire.agent import AgentReply, AgentRequest, AgentState, BeliefsUpdate, StateRequest
from cbdi.wire.world import Sensed
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.desires import Desire
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.requests import serve_request
from cbdi_scheduler.service import SchedulerSettings, scheduler_main

ROVER = Path(__file__).resolve().parent / "rover/agent.toml"
BATTERY = ("battery", "robot1")


def sensed(epoch: int, *add: tuple[str, ...]) -> Sensed:
    return Sensed(agent="robot1", epoch=epoch, time=float(epoch), add=[list(a) for a in add])


def told(op: str, belief: str, threshold: float = 0.0) -> AgentRequest:
    return AgentRequest(
        from_agent="sensor", group="sensors", op=op, belief=belief, threshold=threshold
    )  # type: ignore[arg-type]


def waiting_rover() -> Mind:
    """A rover whose search for (at robot1 c) failed: it waits for the beliefs to change."""
    mind = Mind(load_agent(ROVER, "robot1"))
    mind.request_desire(Desire("go", (fact("at", "robot1", "c"),)))
    started = mind.on_percepts(sensed(0, ("at", "robot1", "a")))
    assert [c.kind for c in started.commands] == ["start_search"]
    waiting = mind.on_search_failed("no plan: the battery is unknown")
    assert [(e.desire, e.event) for e in waiting.events] == [("go", "waiting")]
    return mind


def test_a_value_beyond_the_threshold_is_believed_and_retries_the_search() -> None:
    mind = waiting_rover()
    assert serve_request(mind, told("add_belief", "(= (battery robot1) 42.5)", 0.5)).accepted
    retried = mind.on_percepts(sensed(1))
    assert [c.kind for c in retried.commands] == ["start_search"]
    assert mind.beliefs.fluents[BATTERY] == 42.5
    mind.on_search_failed("no plan: still")
    # Noise: within the threshold of the believed 42.5, no change and no search.
    assert serve_request(mind, told("add_belief", "(= (battery robot1) 42.9)", 0.5)).accepted
    assert serve_request(mind, told("add_belief", "(= (battery robot1) 42.0)", 0.5)).accepted
    quiet = mind.on_percepts(sensed(2))
    assert quiet.commands == [] and mind.beliefs.fluents[BATTERY] == 42.5
    # Beyond it: believed, and the search is tried again.
    assert serve_request(mind, told("add_belief", "(= (battery robot1) 41.9)", 0.5)).accepted
    assert [c.kind for c in mind.on_percepts(sensed(3)).commands] == ["start_search"]
    assert mind.beliefs.fluents[BATTERY] == 41.9


def test_an_event_reaches_the_rules_once_and_is_never_believed() -> None:
    mind = Mind(load_agent(ROVER, "robot1"))
    mind.on_percepts(sensed(0, ("at", "robot1", "a")))
    bumped, alarm = fact("bumped", "robot1"), fact("alarm", "robot1")
    assert serve_request(mind, told("event", "(bumped robot1)")).accepted
    assert serve_request(mind, told("event", "(bumped robot1)")).accepted  # the same: one
    assert not mind.beliefs.holds(bumped)  # not before its cycle
    mind.on_percepts(sensed(1))
    assert mind.beliefs.holds(alarm) and not mind.beliefs.holds(bumped)
    # The alarm is cleared and the rules fire again: the bump is gone, no new alarm.
    assert serve_request(mind, told("del_belief", "(alarm robot1)")).accepted
    mind.on_percepts(sensed(2, ("at", "robot1", "b")))
    assert not mind.beliefs.holds(alarm) and not mind.beliefs.holds(bumped)
    # A second bump fires the rule again.
    serve_request(mind, told("event", "(bumped robot1)"))
    mind.on_percepts(sensed(3))
    assert mind.beliefs.holds(alarm)


def test_a_reading_that_does_not_fit_the_domain_is_refused_naming_what_and_why() -> None:
    mind = Mind(load_agent(ROVER, "robot1"))
    refusals = {
        "(= (battery robot1) nan)": "belief: '(= (battery robot1) nan)': expected a finite"
        " number, got 'nan'",
        "(= (battery robot1) inf)": "expected a finite number, got 'inf'",
        "(= (batery robot1) 3)": "belief: 'batery' is not declared by the domain",
        "(= (battery robot1 a) 3)": "belief: 'battery' takes 1 argument(s), got 2",
        "(= (at robot1 a) 1)": "belief: 'at' is a predicate of the domain, not a function",
        "(battery robot1)": "belief: 'battery' is a function of the domain: give its value",
    }
    for belief, reason in refusals.items():
        reply = serve_request(mind, told("add_belief", belief))
        assert not reply.accepted and reason in reply.reason, (belief, reply.reason)
    for belief, reason in {
        "(= (battery robot1) 3)": "an event is a predicate atom like (bumped robot1), not"
        " (battery robot1) = 3",
        "(bumpd robot1)": "'bumpd' is not declared by the domain",
    }.items():
        reply = serve_request(mind, told("event", belief))
        assert not reply.accepted and reason in reply.reason, (belief, reply.reason)
    assert not mind.beliefs.fluents and not mind.events and not mind.changed


class Battery:
    prototype = Prototype("battery", 1, kind="function", threshold=0.5)

    def __init__(self) -> None:
        self.now: dict[tuple[str, ...], float] = {}

    async def read(self) -> dict[tuple[str, ...], float]:
        return self.now


class Bumps:
    prototype = Prototype("bumped", 1, kind="event")

    def __init__(self) -> None:
        self.now: list[tuple[str, ...]] = []

    async def read(self) -> list[tuple[str, ...]]:
        out, self.now = self.now, []
        return out


async def test_sensors_values_reach_the_planner_and_events_the_rules_on_the_bus() -> None:
    network = MemoryNetwork()
    settings = SchedulerSettings(agent="robot1", agent_file=str(ROVER), load_map=False)
    mind = Mind(load_agent(ROVER, "robot1"))
    shell = TogetherService("robot1/scheduler", settings, scheduler_main(mind, settings))
    task = asyncio.create_task(Together([shell], network, log_level="error").run())
    bus = network.bus()
    battery, bumps, logged = Battery(), Bumps(), io.StringIO()
    sensors = [
        asyncio.create_task(
            run_sensor(bus, "robot1", battery, rate=50.0, log=Log("s", stream=logged))
        ),
        asyncio.create_task(run_sensor(bus, "robot1", bumps, rate=50.0)),
    ]
    state_key = keys.component_rpc("robot1", "scheduler", "state")
    rpc = keys.agent_request("robot1", "sensors")
    planner_sees = BeliefsReceiver()
    updates = messages(bus, keys.scheduler_beliefs("robot1"), BeliefsUpdate, LogSink())
    epoch = 0

    async def cycle() -> None:
        """One epoch's percepts; what the planner then believes is `planner_sees`'s."""
        nonlocal epoch
        await bus.publish(keys.world_percepts("robot1"), encode(sensed(epoch)))
        epoch += 1
        _, update = await anext(updates)
        planner_sees.apply(update)

    async def believed() -> list[str]:
        return (await request(bus, state_key, StateRequest(), AgentState)).beliefs

    try:
        async with asyncio.timeout(10):
            while keys.alive("robot1/scheduler") not in network.tokens:
                await asyncio.sleep(0.01)
            battery.now = {("robot1",): 42.5, ("robot2",): math.nan}
            while "(battery robot1) = 42.5" not in await believed():
                await asyncio.sleep(0.02)
            await cycle()
            assert planner_sees.beliefs is not None
            assert planner_sees.beliefs.fluents[BATTERY] == 42.5
            # Malformed: said at the sensor (what, why), refused or rejected at the
            # scheduler with the reason; it goes on serving.
            assert "bad_reading" in logged.getvalue() and "nan" in logged.getvalue()
            nan = await request(
                bus, rpc, told("add_belief", "(= (battery robot1) nan)"), AgentReply
            )
            assert not nan.accepted and "expected a finite number" in nan.reason
            with pytest.raises(RequestFailedError, match="threshold"):
                await request(
                    bus, rpc, told("add_belief", "(= (battery robot1) 1)", math.nan), AgentReply
                )
            # Noise from elsewhere (within 0.5 of 42.5) changes nothing the planner sees.
            noise = told("add_belief", "(= (battery robot1) 42.8)", 0.5)
            assert (await request(bus, rpc, noise, AgentReply)).accepted
            await cycle()
            assert planner_sees.beliefs.fluents[BATTERY] == 42.5
            battery.now = {("robot1",): 30.0}
            while "(battery robot1) = 30" not in await believed():
                await asyncio.sleep(0.02)
            await cycle()
            assert planner_sees.beliefs.fluents[BATTERY] == 30.0
            # An event: the rule turns it into the alarm; the bump itself is never believed.
            bumps.now = [("robot1",)]
            while not mind.events:  # told: the next cycle's rules see it
                await asyncio.sleep(0.02)
            await cycle()
            assert "(alarm robot1)" in await believed()
            assert fact("alarm", "robot1") in planner_sees.beliefs.beliefs()
            assert fact("bumped", "robot1") not in planner_sees.beliefs.beliefs()
        assert not any(t.done() for t in sensors) and not task.done()
    finally:
        for t in sensors:
            t.cancel()
        task.cancel()
        await asyncio.gather(task, *sensors, return_exceptions=True)
    assert fluent("battery", "robot1", value=30.0) in planner_sees.beliefs.beliefs()
