"""`cbdi inspect` counts what the run's domain registers (`cbdi.counters`), by name."""

from __future__ import annotations

from cbdi import keys
from cbdi.wire import encode
from cbdi.wire.base import Message
from cbdi.wire.world import ActionOutcome, OutcomeStatus, WorldInfo
from cbdi_monitor.inspect import inspect_messages, render
from cbdi_monitor.reader import RecordedMessage
from cbdi_monitor.schemas import peek_schema


def recorded(messages: list[tuple[str, Message]]) -> list[RecordedMessage]:
    out = []
    for i, (key, msg) in enumerate(messages, 1):
        payload = encode(msg)
        out.append(RecordedMessage(key, payload, i, i, i, peek_schema(payload), "msgpack"))
    return out


def info(simulator: str) -> WorldInfo:
    return WorldInfo(
        map_name="m",
        agents=["robot1"],
        epoch_duration=1.0,
        durations={},
        simulator=simulator,
    )


def outcome(action: str, status: OutcomeStatus = "succeeded") -> tuple[str, Message]:
    o = ActionOutcome(
        agent="robot1", request_id=action, action=action, status=status, reason="", epoch=1, time=1
    )
    return keys.world_outcomes("robot1"), o


def run_of(simulator: str, *actions: tuple[str, Message]) -> list[RecordedMessage]:
    return recorded([(keys.world_stream("info"), info(simulator)), *actions])


def test_a_grid_run_counts_moves_and_recycled_as_its_domain_registers() -> None:
    moves = [outcome("move"), outcome("move"), outcome("move", "failed"), outcome("recycle")]
    report = inspect_messages(run_of("recycling", *moves))
    robot = report.agents["robot1"]
    assert report.simulator == "recycling"
    assert robot.counters == {"moves": 2, "recycled": 1} and robot.failed == 1
    assert "agent robot1: moves=2 recycled=1 failed=1" in render(report)


def test_another_domain_reports_its_own_counters_and_no_grid_ones() -> None:
    report = inspect_messages(run_of("courier", outcome("drive"), outcome("drop")))
    robot = report.agents["robot1"]
    assert robot.counters == {"drives": 1, "drops": 1, "charges": 0}
    text = render(report)
    assert "agent robot1: drives=1 drops=1 charges=0 failed=0" in text
    assert "moves=" not in text and "recycled=" not in text


def test_a_domain_that_registers_nothing_shows_its_actions_by_name_only() -> None:
    report = inspect_messages(run_of("clock", outcome("carry")))
    robot = report.agents["robot1"]
    assert robot.counters == {} and robot.actions == {"carry:succeeded": 1}
    assert "agent robot1: failed=0" in render(report)
