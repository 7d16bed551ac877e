"""The host's side of recovery (`WorldService` with a state file), on the in-memory bus.

A request asked again (an executor that lost the reply with the killed world) is served
once; a restarted world replays the steps and requests noted since the last whole save
and publishes the epoch it reached again (in real time too: its outcomes are news).
"""

from __future__ import annotations

import io
from pathlib import Path

from cbdi import keys
from cbdi.bus import LogSink, MemoryBus, messages
from cbdi.runtime.log import Log
from cbdi.runtime.service import ServiceContext
from cbdi.wire.common import RunFinished
from cbdi.wire.world import ActionOutcome, ActionReply, ActionRequest, EpochAck, Tick
from cbdi_world.recovery import Keeper
from cbdi_world.service import WorldService, WorldSettings, build_world
from tests_support import REPO

MAP = str(REPO / "domains/recycling/maps/paper-7x7.toml")


def host(
    state: Path,
    bus: MemoryBus,
    out: io.StringIO,
    restart: int = 0,
    lockstep: bool = True,
    max_time: float = 0.0,
) -> WorldService:
    settings = WorldSettings(
        simulator="recycling",
        map=MAP,
        seed=1,
        state=str(state),
        state_every=5,
        restart=restart,
        lockstep=lockstep,
        max_time=max_time,
    )
    ctx = ServiceContext("world", bus, Log("world", stream=out), settings)
    keeper = Keeper(state, ctx.log)
    world = build_world(settings)
    recovered = keeper.recover(world) if restart else None
    service = WorldService(ctx, recovered[0] if recovered else world, settings, keeper=keeper)
    if recovered:
        service.resume(recovered[1])
    return service


def move(request_id: str, target: tuple[int, int]) -> ActionRequest:
    return ActionRequest(agent="robot1", action="move", request_id=request_id, target=target)


async def test_a_request_asked_again_is_served_once(tmp_path: Path) -> None:
    out = io.StringIO()
    world = host(tmp_path / "world.state", MemoryBus(), out)
    await world.advance(world.world.initial())
    x, y = world.world.agents["robot1"].cell  # type: ignore[attr-defined]
    first = await world.on_act("act", move("robot1-1", (x + 1, y)))
    again = await world.on_act("act", move("robot1-1", (x + 1, y)))
    assert isinstance(first, ActionReply) and first.accepted and again == first
    assert world.trace.count == 1 and "event=act_repeated" in out.getvalue()
    other = await world.on_act("act", move("robot1-2", (x + 1, y)))  # a new one: busy
    assert isinstance(other, ActionReply) and not other.accepted


async def test_a_restart_replays_what_followed_the_save_and_publishes_what_did_not_go_out(
    tmp_path: Path,
) -> None:
    state, out = tmp_path / "world.state", io.StringIO()
    first = host(state, MemoryBus(), out)
    await first.advance(first.world.initial())
    x, y = first.world.agents["robot1"].cell  # type: ignore[attr-defined]
    for epoch in range(1, 8):  # whole saves at 0 and 5, steps noted in between
        target = (x + 1, y) if epoch % 2 else (x, y)
        await first.on_act("act", move(f"robot1-{epoch}", target))
        await first.advance(first.world.step())
    await first.on_act("act", move("robot1-8", (x + 1, y)))
    first.save(first.world.step())  # killed after the step was saved, before publishing
    bus = MemoryBus()
    ticks = messages(bus, keys.world_stream("clock"), Tick, LogSink())
    second = host(state, bus, out, restart=1)
    assert second.resumed is not None
    result, published = second.resumed
    assert (result.epoch, published, second.saved_at) == (8, False, 5)
    assert second.world.stats() == first.world.stats()
    assert second.trace.digest() == first.trace.digest() and second.trace.count == 8
    assert result.snapshot == first.world.snapshot()  # type: ignore[attr-defined]
    await second.go_on(result, published)
    _, tick = await anext(ticks)
    assert tick.epoch == 8 and "event=recovered" in out.getvalue()
    assert "replay_differs" not in out.getvalue()


async def test_a_lockstep_run_says_what_was_sent_before_its_last_epoch(
    tmp_path: Path,
) -> None:
    """`RunFinished.sent`: the world's own counts and the members' acks of the epoch
    before the last, not what the last tick set off (an ack of it, a request served after
    the world was done), however quickly that came."""
    bus = MemoryBus()
    ended = messages(bus, keys.world_stream("events"), RunFinished, LogSink())
    world = host(tmp_path / "world.state", bus, io.StringIO(), max_time=2.0)
    status = keys.executor_status("robot1")
    await world.advance(world.world.initial())
    x, y = world.world.agents["robot1"].cell  # type: ignore[attr-defined]
    await world.on_act("act", move("robot1-1", (x + 1, y)))
    await world.acks.observe(EpochAck(agent="robot1", epoch=0, sent={status: 3}))
    await world.advance(world.world.step())
    await world.acks.observe(EpochAck(agent="robot1", epoch=1, sent={status: 5}))
    await world.advance(world.world.step())  # epoch 2: time is up
    await world.acks.observe(EpochAck(agent="robot1", epoch=2, sent={status: 9}))
    await world.on_act("act", move("robot1-2", (x, y)))  # set off by the last tick
    _, last = await anext(ended)
    assert (last.reason, last.epoch, last.requests) == ("time_limit", 2, 1)
    assert last.sent[status] == 5 and last.sent[keys.CLOCK] == 2  # ticks of epochs 0 and 1


async def test_an_ack_seen_before_the_state_file_is_read_is_not_taken_back(
    tmp_path: Path,
) -> None:
    """A member sends its latest ack again the moment the world's token is back, which
    may be before the restarted world has read its state file: the state file's older
    marks must not overwrite it (the run then stalled for an ack timeout)."""
    from cbdi.lockstep import stage_rank
    from cbdi.wire.world import EpochAck

    world = host(tmp_path / "world.state", MemoryBus(), io.StringIO())
    await world.acks.observe(EpochAck(agent="robot1", epoch=10, component="executor"))
    member, done = keys.member("robot1", "executor"), stage_rank("done")
    world.restore_marks({member: (9, done)}, {member: 10}, {member: 1})
    assert world.acks.acked[member] == (10, done)  # the later mark stays
    assert world.acks.waiting_for(10, "done") == []  # caught up: not behind
    world.restore_marks({member: (12, done)}, {}, {})
    assert world.acks.acked[member] == (12, done)  # a later saved mark is taken


async def test_a_real_time_world_killed_after_publishing_sends_that_epochs_outcomes_again(
    tmp_path: Path,
) -> None:
    """Killed just after publishing (Zenoh may not have sent it yet), a real-time world
    publishes that epoch again: the next epoch brings new percepts, but the outcome of an
    action that ended in it comes only with it (its executor waited for good, seen under
    load in tests/e2e/test_faults.py)."""
    state, out = tmp_path / "world.state", io.StringIO()
    first = host(state, MemoryBus(), out, lockstep=False)
    await first.advance(first.world.initial())
    x, y = first.world.agents["robot1"].cell  # type: ignore[attr-defined]
    await first.on_act("act", move("robot1-1", (x + 1, y)))
    await first.advance(first.world.step())  # the move ends: its outcome went out (lost)
    bus = MemoryBus()
    outcomes = messages(bus, keys.world_outcomes("robot1"), ActionOutcome, LogSink())
    second = host(state, bus, out, restart=1, lockstep=False)
    assert second.resumed is not None
    result, published = second.resumed
    assert (result.epoch, published) == (1, True)
    await second.go_on(result, published)
    _, outcome = await anext(outcomes)
    assert (outcome.request_id, outcome.status, outcome.epoch) == ("robot1-1", "succeeded", 1)
