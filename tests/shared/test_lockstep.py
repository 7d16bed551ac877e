"""The epoch gate: what an ack covers is released, in the sender's order, nothing else;
a member's latest ack goes again to a restarted world."""

from __future__ import annotations

import asyncio

import pytest
from cbdi_recycling.wire import Percepts

from cbdi import keys, lockstep
from cbdi.bus import LogSink, MemoryNetwork, messages
from cbdi.bus.typed import Stamped, serve
from cbdi.lockstep import WORLD, EpochGate, Lockstep, Need, resend_latest_ack, send_ack
from cbdi.wire.agent import BeliefsUpdate
from cbdi.wire.base import Message
from cbdi.wire.world import (
    EpochAck,
    Tick,
    WorldInfo,
    WorldInfoRequest,
)
from tests_support import settle

BELIEFS = "cbdi/r1/scheduler/beliefs"
PLANS = "cbdi/r1/scheduler/plans"
S = "r1/scheduler"


def beliefs(epoch: int) -> BeliefsUpdate:
    return BeliefsUpdate(
        agent="r1", epoch=epoch, time=float(epoch), instances={}, facts=[], fluents=[]
    )


def ack(epoch: int, sent: dict[str, int], stage: str = "done", seq: int = 1) -> Stamped:
    msg = EpochAck(agent="r1", component="scheduler", epoch=epoch, stage=stage, sent=sent)  # type: ignore[arg-type]
    return Stamped("cbdi/r1/scheduler/ack", seq, 0, msg)


def item(key: str, seq: int, order: int, msg: Message) -> Stamped:
    return Stamped(key, seq, order, msg)


async def test_an_ack_releases_what_it_covers_in_the_senders_order() -> None:
    gate = EpochGate([BELIEFS, PLANS, "cbdi/r1/scheduler/ack"])
    # Two subscriptions deliver out of the sender's order: the plan (order 2) first.
    await gate.put(item(PLANS, 1, 2, beliefs(0)))
    await gate.put(item(BELIEFS, 1, 1, beliefs(0)))
    await gate.put(item(BELIEFS, 2, 3, beliefs(1)))  # epoch 1's: after the ack below
    assert not gate.met(Need(S, 0))
    await gate.put(ack(0, {BELIEFS: 1, PLANS: 1, "cbdi/r1/scheduler/desires": 5}))
    assert gate.met(Need(S, 0))  # the desires it sent are not ours to wait for
    released = await gate.wait([Need(S, 0)], timeout=1)
    assert [k for k, _ in released.messages] == [BELIEFS, PLANS] and not released.late
    await gate.put(ack(1, {BELIEFS: 2, PLANS: 1}))
    later = await gate.wait([Need(S, 1)], timeout=1)
    assert [(k, m.epoch) for k, m in later.messages] == [(BELIEFS, 1)]  # type: ignore[attr-defined]


async def test_an_ack_waits_for_the_messages_it_counts() -> None:
    gate = EpochGate([BELIEFS, "cbdi/r1/scheduler/ack"])
    await gate.put(ack(0, {BELIEFS: 1}))  # the ack overtook the beliefs
    assert not gate.met(Need(S, 0))
    await gate.put(item(BELIEFS, 1, 1, beliefs(0)))
    assert gate.met(Need(S, 0))


async def test_the_start_takes_only_what_came_before_ready() -> None:
    gate = EpochGate([BELIEFS, "cbdi/r1/scheduler/ack"])
    await gate.put(ack(-1, {}, stage="ready"))
    await gate.put(item(BELIEFS, 1, 1, beliefs(0)))  # epoch 0's, early
    assert (await gate.wait([Need(S, -1)], timeout=1)).messages == []
    await gate.put(ack(0, {BELIEFS: 1}))
    assert len((await gate.wait([Need(S, 0)], timeout=1)).messages) == 1


async def test_the_world_is_released_up_to_the_agents_percepts() -> None:
    gate = EpochGate(["cbdi/world/clock", "cbdi/world/*/r1"])
    tick = Tick(epoch=0, time=0.0, epoch_duration=1.0, speed=0.0, lockstep=True)
    seen = Percepts(
        agent="r1",
        epoch=0,
        time=0.0,
        position=(0, 0),
        depth=1,
        free=[],
        blocked=[],
        items=[],
        holding=[],
    )
    await gate.put(item("cbdi/world/clock", 1, 1, tick))
    assert not gate.met(Need(WORLD, 0))
    await gate.put(item("cbdi/world/percepts/r1", 1, 2, seen))
    released = await gate.wait([Need(WORLD, 0)], timeout=1)
    assert [type(m).__name__ for _, m in released.messages] == ["Tick", "Percepts"]


async def test_the_percepts_wait_for_the_tick_and_outcomes_they_count() -> None:
    """After a router restart the bus recovers each key on its own: the percepts (the
    world's last message of the epoch) may come before the tick or an outcome they
    count. The gate waits for those, releases them in the world's order, and leaves
    the next epoch's for later; a late joiner takes the counts it never saw as had."""
    from cbdi.wire.world import ActionOutcome

    clock, outcomes, percepts = (
        "cbdi/world/clock",
        "cbdi/world/outcomes/r1",
        "cbdi/world/percepts/r1",
    )
    gate = EpochGate(["cbdi/world/clock", "cbdi/world/*/r1"])

    def tick(e: int) -> Tick:
        return Tick(epoch=e, time=float(e), epoch_duration=1.0, speed=0.0, lockstep=True)

    def seen(e: int, sent: dict[str, int]) -> Percepts:
        return Percepts(
            agent="r1", epoch=e, time=float(e), position=(0, 0), depth=1,
            free=[], blocked=[], items=[], holding=[], sent=sent,
        )  # fmt: skip

    done = ActionOutcome(
        agent="r1", request_id="a", action="move", status="succeeded", reason="", epoch=1, time=1.0
    )
    await gate.put(item(clock, 1, 1, tick(0)))
    await gate.put(item(percepts, 1, 2, seen(0, {clock: 1})))
    assert gate.met(Need(WORLD, 0))
    await gate.wait([Need(WORLD, 0)], timeout=1)
    await gate.put(item(percepts, 2, 5, seen(1, {clock: 2, outcomes: 1})))  # came first
    assert not gate.met(Need(WORLD, 1))
    await gate.put(item(outcomes, 1, 4, done))
    assert not gate.met(Need(WORLD, 1))
    await gate.put(item(clock, 2, 3, tick(1)))
    await gate.put(item(clock, 3, 6, tick(2)))  # epoch 2's: not covered
    released = await gate.wait([Need(WORLD, 1)], timeout=1)
    names = [type(m).__name__ for _, m in released.messages]
    assert names == ["Tick", "ActionOutcome", "Percepts"] and not released.late
    late = EpochGate(["cbdi/world/clock", "cbdi/world/*/r1"])
    late.rebase, late.joined = True, 5
    await late.put(item(clock, 6, 9, tick(5)))
    await late.put(item(percepts, 6, 10, seen(5, {clock: 6, outcomes: 3})))
    assert late.met(Need(WORLD, 5))


async def test_a_restarted_worlds_repeat_of_an_epoch_released_is_had_not_handled_twice() -> None:
    """A world killed right after it published epoch k cannot know whether that went
    out: its restart publishes epoch k again. A gate that released k counts the repeat as
    received (the next percepts count it) and hands none of it out; a gate that had lost
    k (it never came) gets it from the repeat."""
    from cbdi.wire.world import ActionOutcome

    clock, outcomes, percepts = (
        "cbdi/world/clock",
        "cbdi/world/outcomes/r1",
        "cbdi/world/percepts/r1",
    )

    def tick(e: int) -> Tick:
        return Tick(epoch=e, time=float(e), epoch_duration=1.0, speed=0.0, lockstep=True)

    def seen(e: int, sent: dict[str, int]) -> Percepts:
        return Percepts(
            agent="r1", epoch=e, time=float(e), position=(0, 0), depth=1,
            free=[], blocked=[], items=[], holding=[], sent=sent,
        )  # fmt: skip

    def done(e: int) -> ActionOutcome:
        return ActionOutcome(
            agent="r1", request_id=f"a{e}", action="move", status="succeeded", reason="",
            epoch=e, time=float(e),
        )  # fmt: skip

    async def old_life(gate: EpochGate, epochs: int) -> None:
        for e in range(epochs):  # ticks 0..e, an outcome each epoch from 1 on
            await gate.put(item(clock, e + 1, 3 * e, tick(e)))
            if e:
                await gate.put(item(outcomes, e, 3 * e + 1, done(e)))
            await gate.put(item(percepts, e + 1, 3 * e + 2, seen(e, {outcomes: e} if e else {})))
            await gate.wait([Need(WORLD, e)], timeout=1)

    had = EpochGate([clock, "cbdi/world/*/r1"])
    await old_life(had, 11)  # epochs 0..10 released
    # The new life: epoch 10 again (new counts), then epoch 11.
    await had.put(item(clock, 1, 1, tick(10)))
    await had.put(item(outcomes, 1, 2, done(10)))
    await had.put(item(percepts, 1, 3, seen(10, {outcomes: 1})))
    await had.put(item(clock, 2, 4, tick(11)))
    await had.put(item(outcomes, 2, 5, done(11)))
    assert not had.met(Need(WORLD, 11))
    await had.put(item(percepts, 2, 6, seen(11, {outcomes: 2})))
    released = await had.wait([Need(WORLD, 11)], timeout=1)
    assert not released.late
    assert [(type(m).__name__, m.epoch) for _, m in released.messages] == [  # type: ignore[attr-defined]
        ("Tick", 11),
        ("ActionOutcome", 11),
        ("Percepts", 11),
    ]

    lost = EpochGate([clock, "cbdi/world/*/r1"])
    await old_life(lost, 10)  # epoch 10 never came: the gate waits for it
    assert not lost.met(Need(WORLD, 10))
    await lost.put(item(clock, 1, 1, tick(10)))
    await lost.put(item(outcomes, 1, 2, done(10)))
    await lost.put(item(percepts, 1, 3, seen(10, {outcomes: 1})))
    again = await lost.wait([Need(WORLD, 10)], timeout=1)
    assert [m.epoch for _, m in again.messages] == [10, 10, 10] and not again.late  # type: ignore[attr-defined]


async def test_a_late_sender_is_named_and_what_came_is_taken() -> None:
    gate = EpochGate([BELIEFS, "cbdi/r1/scheduler/ack"])
    await gate.put(item(BELIEFS, 1, 1, beliefs(0)))
    released = await gate.wait([Need(S, 0)], timeout=0.05)
    assert released.late == [S] and len(released.messages) == 1


async def test_senders_outside_lockstep_are_let_through() -> None:
    gate = EpochGate([BELIEFS, "cbdi/r1/planner/plans"])
    gate.members = {S}
    await gate.put(item("cbdi/r1/planner/plans", 1, 1, beliefs(0)))  # not a member
    await gate.put(item(BELIEFS, 1, 1, beliefs(0)))  # a member: waits for its ack
    released = await gate.wait([], timeout=1)
    assert [k for k, _ in released.messages] == ["cbdi/r1/planner/plans"]


async def test_a_restarted_senders_earlier_life_is_not_released_among_its_new_one() -> None:
    """An update the killed sender sent that no ack released (its ack never came) must
    not come out once the restarted sender's counts pass its number."""
    gate = EpochGate([BELIEFS, "cbdi/r1/scheduler/ack"])
    await gate.put(item(BELIEFS, 13, 40, beliefs(12)))  # the old life's last, unacked
    await gate.put(item(BELIEFS, 1, 1, beliefs(14)))  # the new life starts afresh
    for seq in range(2, 14):
        await gate.put(item(BELIEFS, seq, seq, beliefs(13 + seq)))
    await gate.put(ack(26, {BELIEFS: 13}))
    released = await gate.wait([Need(S, 26)], timeout=1)
    epochs = [m.epoch for _, m in released.messages]  # type: ignore[attr-defined]
    assert epochs == list(range(14, 27)), epochs


async def test_a_restarted_senders_first_ack_is_kept_whichever_key_comes_first() -> None:
    """Keys arrive in no common order: the new life's first ack may come before its first
    message. That message (counts gone back) must not drop the ack it came after, nor may
    the old life's acks meet a need of the new one (a stall until the ack timeout)."""
    for ack_first in (True, False):
        gate = EpochGate([BELIEFS, "cbdi/r1/scheduler/ack"])
        for seq in range(1, 11):  # the old life: epochs 0 to 9
            await gate.put(item(BELIEFS, seq, seq, beliefs(seq - 1)))
            await gate.put(ack(seq - 1, {BELIEFS: seq}, seq=seq))
        await gate.put(item(BELIEFS, 11, 11, beliefs(10)))  # killed before its ack of 10
        new_ack = ack(11, {BELIEFS: 1}, seq=1)
        new_beliefs = item(BELIEFS, 1, 12, beliefs(11))
        for it in (new_ack, new_beliefs) if ack_first else (new_beliefs, new_ack):
            await gate.put(it)
        released = await gate.wait([Need(S, 11)], timeout=1)
        assert not released.late, ack_first
        assert [m.epoch for _, m in released.messages] == [11], ack_first  # type: ignore[attr-defined]


async def test_a_member_sends_its_latest_ack_again_when_the_world_comes_back() -> None:
    """A restarted world lost the acks its predecessor got: each member sends its latest
    one again, the very same message, when the world's token comes back (not for the
    world it already knew)."""
    network = MemoryNetwork()
    world, member = network.bus(), network.bus()
    token = await world.declare_token(keys.alive("world"))
    heard = messages(network.bus(), keys.epoch_ack("r1", "executor"), EpochAck, LogSink())
    await send_ack(member, "r1", "executor", 7)
    _, sent = await anext(heard)
    resend = asyncio.create_task(resend_latest_ack(member, "r1", "executor"))
    await settle()  # the world it knows: nothing sent
    await token.close()  # killed ...
    await settle()
    await world.declare_token(keys.alive("world"))  # ... and back
    async with asyncio.timeout(5):
        _, again = await anext(heard)
    assert again == sent and again.epoch == 7
    resend.cancel()
    assert member.sent[keys.epoch_ack("r1", "executor")] == 2  # once, and once again


async def test_a_world_not_up_yet_is_asked_again_not_taken_for_none(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A member that starts before its world: the failed ask is not kept as the answer
    (a later input, once the world is up, finds the run a lockstep one)."""
    monkeypatch.setattr(lockstep, "ASK_WORLD", 0.1)
    network = MemoryNetwork()
    bus = network.bus()
    step = Lockstep([keys.world_stream("clock")], lambda first: None, bus=bus, me=S)
    assert not await step.rejoin()
    assert step.lockstep_member is None
    info = WorldInfo(
        map_name="m", agents=["r1"], epoch_duration=1.0, durations={},
        members=[S], lockstep=True,
    )  # fmt: skip

    async def answer(key: str, req: WorldInfoRequest) -> WorldInfo:
        return info

    world = asyncio.create_task(
        serve(network.bus(), keys.world_rpc("info"), WorldInfoRequest, answer, LogSink())
    )
    await settle()
    early = Stamped(PLANS, 1, 1, beliefs(0))
    assert await step.put(early) == []  # kept for the first tick, not handled at once
    assert step.lockstep_member is True and step.early == [early]
    world.cancel()


async def test_a_lost_sample_costs_one_timeout_not_one_per_epoch() -> None:
    """An ack counts a sample that never comes (lost on the way, on a key sent on once):
    the gate waits for it once, then takes it as lost; the next epoch's ack, counting
    it still, is met at once."""
    gate = EpochGate([BELIEFS])
    await gate.put(ack(0, {BELIEFS: 1}))
    first = await gate.wait([Need(S, 0)], 0.05)
    assert first.late == [S] and first.messages == []
    await gate.put(ack(1, {BELIEFS: 1}, seq=2))
    second = await gate.wait([Need(S, 1)], 30.0)
    assert second.late == []
    # It comes after all: taken at the next gate, as anything late is.
    await gate.put(item(BELIEFS, 1, 1, beliefs(0)))
    await gate.put(ack(2, {BELIEFS: 1}, seq=3))
    third = await gate.wait([Need(S, 2)], 30.0)
    assert third.late == [] and third.messages == [(BELIEFS, beliefs(0))]


async def test_a_repeated_epoch_makes_a_member_send_its_ack_again() -> None:
    """A restarted world publishes the epoch it was stopped in again. Its token may come
    before its predecessor's goes (a killed process's lease not yet out), so the token
    watch sees no change: the repeat itself makes the member say its ack again."""
    network = MemoryNetwork()
    member = network.bus()
    heard = messages(network.bus(), keys.epoch_ack("r1", "scheduler"), EpochAck, LogSink())
    step = Lockstep([keys.world_stream("clock")], lambda first: None, bus=member, me=S)
    clock = keys.world_stream("clock")

    def tick(epoch: int, seq: int) -> Stamped:
        t = Tick(epoch=epoch, time=float(epoch), epoch_duration=1.0, speed=0.0, lockstep=True)
        return Stamped(clock, seq, seq, t)

    await step.put(tick(0, 1))  # lockstep decided
    await send_ack(member, "r1", "scheduler", 4)
    _, sent = await anext(heard)
    await step.put(tick(5, 2))  # a new epoch: nothing said again
    await step.put(tick(4, 1))  # the restarted world's repeat of epoch 4
    async with asyncio.timeout(5):
        _, again = await anext(heard)
    assert again == sent and member.sent[keys.epoch_ack("r1", "scheduler")] == 2


def test_the_gate_hears_by_zenoh_rules_and_never_a_key_zenoh_refuses() -> None:
    gate = EpochGate([keys.CLOCK, keys.world_for_agent("r1"), keys.epoch_ack("*", "scheduler")])
    assert gate.hears(keys.CLOCK) and gate.hears(keys.world_percepts("r1"))
    assert gate.hears(keys.epoch_ack("r2", "scheduler"))
    assert not gate.hears(keys.world_percepts("r2"))
    assert not gate.hears("cbdi//clock")  # an ack's garbage: nothing to wait for


async def test_the_epochs_go_stage_by_stage_each_acknowledged_after_its_body() -> None:
    """`Lockstep.epochs`, the one way in: each stage waits for its needs, yields what
    they released, and is acknowledged (with what the body sent) only once the body is
    done; a need not met is given up after the timeout and its sender logged late."""
    from cbdi.runtime.log import Log

    network = MemoryNetwork()
    member = network.bus()
    heard = messages(network.bus(), keys.epoch_ack("r1", "scheduler"), EpochAck, LogSink())
    step = Lockstep([BELIEFS, "cbdi/r1/planner/ack"], lambda first: None, bus=member, me=S)
    asked: list[tuple[int, str, frozenset[str]]] = []

    def needs(epoch: int, stage: str, members: frozenset[str]) -> list[Need]:
        asked.append((epoch, stage, members))
        return [Need("r1/planner", epoch)] if stage == "done" else []

    def planner_ack(epoch: int) -> Stamped:
        msg = EpochAck(agent="r1", component="planner", epoch=epoch, stage="done", sent={})
        return Stamped("cbdi/r1/planner/ack", epoch + 1, epoch + 1, msg)

    await step.gate.put(planner_ack(0))
    import io

    stream = io.StringIO()
    log = Log("scheduler", stream=stream)
    seen: list[tuple[int, str, list[str]]] = []
    epochs = step.epochs(0, needs, 0.05, log, ("beliefs", "done"), [S, "r1/planner"])
    async for epoch in epochs:
        seen.append((epoch.number, epoch.stage, epoch.late))
        await member.publish(PLANS, b"x")  # the body's sending, in the ack after it
        if len(seen) == 4:
            break
    assert seen == [(0, "beliefs", []), (0, "done", []), (1, "beliefs", []),
                    (1, "done", ["r1/planner"])]  # fmt: skip
    assert [a[:2] for a in asked] == [(0, "beliefs"), (0, "done"), (1, "beliefs"), (1, "done")]
    assert asked[0][2] == {S, "r1/planner"}
    acks = [(await anext(heard))[1] for _ in range(3)]  # the fourth body never ended
    assert [(a.epoch, a.stage, a.sent.get(PLANS)) for a in acks] == [
        (0, "beliefs", 1), (0, "done", 2), (1, "beliefs", 3)
    ]  # fmt: skip
    assert "event=upstream_late epoch=1 late=r1/planner" in stream.getvalue()
