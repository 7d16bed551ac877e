"""Sensors (`cbdi.sensor`): readings become belief additions and deletions through the
agent's request endpoint, checked against the domain (the scheduler's shell on the
in-memory bus)."""

from __future__ import annotations

import asyncio
import io
import math
from functools import partial

import pytest

from cbdi import keys
from cbdi.bus import MemoryNetwork, request
from cbdi.runtime.log import Log
from cbdi.runtime.together import Together, TogetherService
from cbdi.sensor import Change, Prototype, SensorLoop, run_sensor
from cbdi.wire.agent import AgentReply, AgentState, StateRequest
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.service import SchedulerSettings, scheduler_main
from tests_support import REPO

AGENT = REPO / "domains/recycling/agents/recycler.toml"


class Cells:
    """Senses which cells are free; the test sets what it reads."""

    def __init__(self, predicate: str = "free") -> None:
        self.prototype = Prototype(predicate, 1)
        self.now: list[tuple[str, ...]] = []
        self.reads = 0

    async def read(self) -> list[tuple[str, ...]]:
        self.reads += 1
        return self.now


def test_the_loop_tells_changes_once_and_leaves_refusals_until_the_reading_changes() -> None:
    loop = SensorLoop("robot1", Cells())
    add, delete = partial(Change, op="add_belief"), partial(Change, op="del_belief")
    assert loop.changes([("c_1_1",), ("c_2_2",), ("a", "b")]) == [add(("c_1_1",)), add(("c_2_2",))]
    assert loop.rejected == ["expected 1 argument(s), got 2: ('a', 'b')"]
    loop.answered(add(("c_1_1",)), AgentReply(accepted=True))
    loop.answered(add(("c_2_2",)), AgentReply(accepted=False, reason="no"))
    assert loop.changes([("c_1_1",), ("c_2_2",)]) == []  # told, and refused: not again
    assert loop.changes([]) == [delete(("c_1_1",))]  # c_2_2's refusal is forgotten
    assert loop.changes([("c_2_2",)]) == [add(("c_2_2",)), delete(("c_1_1",))]
    assert loop.request(add(("c_2_2",))).belief == "(free c_2_2)"


async def test_a_sensor_adds_and_deletes_beliefs_of_its_prototype() -> None:
    network = MemoryNetwork()
    settings = SchedulerSettings(agent="robot1", agent_file=str(AGENT), load_map=False)
    mind = Mind(load_agent(AGENT, "robot1"))
    shell = TogetherService("robot1/scheduler", settings, scheduler_main(mind, settings))
    task = asyncio.create_task(Together([shell], network, log_level="error").run())
    bus = network.bus()
    cells, typo = Cells(), Cells("fre")
    logged = io.StringIO()
    sensors = [
        asyncio.create_task(run_sensor(bus, "robot1", cells, rate=50.0)),
        asyncio.create_task(
            run_sensor(bus, "robot1", typo, rate=50.0, log=Log("s", stream=logged))
        ),
    ]
    state_key = keys.component_rpc("robot1", "scheduler", "state")

    async def believes(literal: str) -> bool:
        state = await request(bus, state_key, StateRequest(), AgentState)
        return literal in state.beliefs

    try:
        async with asyncio.timeout(10):
            while keys.alive("robot1/scheduler") not in network.tokens:
                await asyncio.sleep(0.01)
            cells.now = [("c_5_5",)]
            typo.now = [("c_5_5",)]
            while not await believes("(free c_5_5)"):
                await asyncio.sleep(0.02)
            cells.now = []
            while await believes("(free c_5_5)"):
                await asyncio.sleep(0.02)
            while "refused" not in logged.getvalue():
                await asyncio.sleep(0.02)
        assert "fre" in logged.getvalue() and logged.getvalue().count("refused") == 1
        assert not await believes("(fre c_5_5)")
        assert cells.reads > 2 and not any(t.done() for t in sensors)
    finally:
        for t in sensors:
            t.cancel()
        task.cancel()
        await asyncio.gather(task, *sensors, return_exceptions=True)


class Battery:
    """Senses (battery ?r): the test sets what it reads."""

    prototype = Prototype("battery", 1, kind="function", threshold=0.5)

    def __init__(self) -> None:
        self.now: dict[tuple[str, ...], float] = {}

    async def read(self) -> dict[tuple[str, ...], float]:
        return self.now


class Bumps:
    """Senses (bumped ?r) events: each read gives those since the last and forgets them."""

    prototype = Prototype("bumped", 1, kind="event")

    def __init__(self) -> None:
        self.now: list[tuple[str, ...]] = []

    async def read(self) -> list[tuple[str, ...]]:
        out, self.now = self.now, []
        return out


def test_a_function_sensor_tells_a_value_once_it_moves_beyond_its_threshold() -> None:
    loop = SensorLoop("robot1", Battery())
    first = loop.changes({("robot1",): 42.5})
    assert first == [Change(("robot1",), "add_belief", 42.5)]
    request = loop.request(first[0])
    assert (request.belief, request.threshold) == ("(= (battery robot1) 42.5)", 0.5)
    loop.answered(first[0], AgentReply(accepted=True))
    assert loop.changes({("robot1",): 42.9}) == []  # noise: within 0.5 of what was told
    assert loop.changes({("robot1",): 41.9}) == [Change(("robot1",), "add_belief", 41.9)]
    assert loop.changes({}) == []  # no longer read: it keeps its last value
    # A refused value is not sent again until it moves beyond the threshold.
    loop.answered(Change(("robot1",), "add_belief", 41.9), AgentReply(accepted=False))
    assert loop.changes({("robot1",): 42.0}) == []
    assert loop.changes({("robot1",): 40.0}) == [Change(("robot1",), "add_belief", 40.0)]


def test_readings_that_do_not_fit_the_prototype_are_left_out_with_the_reason() -> None:
    loop = SensorLoop("robot1", Battery())
    reading = {
        ("robot1",): math.nan,
        ("robot2",): math.inf,
        ("robot3", "x"): 1.0,
        ("a b",): 1.0,
        ("robot4",): 7.0,
    }
    assert loop.changes(reading) == [Change(("robot4",), "add_belief", 7.0)]
    assert loop.rejected == [
        "value nan of (battery robot1) is not a finite number",
        "value inf of (battery robot2) is not a finite number",
        "expected 1 argument(s), got 2: ('robot3', 'x')",
        "argument 'a b' is not a name (no spaces or parentheses)",
    ]
    assert loop.changes({("robot1",): "full"}) == []  # type: ignore[dict-item]
    assert loop.rejected == ["value 'full' of (battery robot1) is not a finite number"]
    with pytest.raises(ValueError, match="only a function's readings have a threshold"):
        Prototype("bumped", 1, kind="event", threshold=1.0)
    with pytest.raises(ValueError, match="threshold nan is not a number >= 0"):
        Prototype("battery", 1, kind="function", threshold=math.nan)


def test_an_event_is_told_once_and_again_only_if_the_agent_did_not_answer() -> None:
    loop = SensorLoop("robot1", Bumps())
    bump = Change(("robot1",), "event")
    assert loop.changes([("robot1",)]) == [bump]
    assert loop.request(bump).op == "event" and loop.request(bump).belief == "(bumped robot1)"
    assert loop.changes([]) == [bump]  # not answered (the scheduler was away): again
    loop.answered(bump, AgentReply(accepted=True))
    assert loop.changes([]) == []  # told: never again
    assert loop.changes([("robot1",), ("robot1",)]) == [bump, bump]  # two bumps
