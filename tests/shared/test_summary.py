"""What `cbdi up` counts of a run (`cbdi.launcher.summary.RunCounts`): counts that do not
hang on the order in which two keys' messages arrive, nor on when the run stopped
listening."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Iterable

from cbdi import keys, tally
from cbdi.bus.typed import Stamped
from cbdi.launcher.summary import ACTS, RunCounts, RunSummary, counted_keys
from cbdi.wire.agent import ActionStatus
from cbdi.wire.world import ActionRequest, Tick
from tests_support import settle

A = "robot1"


def tick(order: int, epoch: int) -> Stamped:
    msg = Tick(epoch=epoch, time=float(epoch), epoch_duration=1.0, speed=0.0, lockstep=True)
    return Stamped(keys.CLOCK, epoch + 1, order, msg)


def act(order: int, seq: int) -> Stamped:
    return Stamped(ACTS, seq, order, ActionRequest(agent=A, action="move", request_id=f"r{seq}"))


def running(seq: int, step: str) -> Stamped:
    msg = ActionStatus(
        agent=A, plan_id="p1", step_id=step, action="move", status="running", reason="", time=0
    )
    return Stamped(keys.executor_status(A), seq, 0, msg)


async def stream(samples: Iterable[Stamped]) -> AsyncIterator[Stamped]:
    for s in samples:
        yield s


async def counted(*samples: Stamped, upto: dict[str, int] | None = None) -> RunSummary:
    summary, counts = RunSummary(scenario="test"), RunCounts(tally.PlannerTally())
    await counts.listen(stream(samples))
    if upto is not None:
        await counts.cover(upto, counted_keys([A]), timeout=1)
    counts.fold(summary)
    return summary


async def test_the_first_action_is_timed_by_the_worlds_order_not_by_arrival() -> None:
    # The world served the request (order 6) after its tick of epoch 1 (order 5): the tick
    # arriving late changes nothing; nor does a request of epoch 0 arriving after it.
    late_tick = await counted(tick(1, 0), act(6, 2), tick(5, 1))
    in_order = await counted(tick(1, 0), tick(5, 1), act(6, 2))
    early = await counted(tick(1, 0), tick(5, 1), act(6, 2), act(3, 1))
    assert late_tick.actions[A] == in_order.actions[A] == {"actions": 1, "first_action": 1.0}
    assert early.actions[A] == {"actions": 2, "first_action": 0.0}


async def test_a_step_is_performed_once_however_often_it_is_reported_running() -> None:
    summary = await counted(running(1, "p1-1"), running(2, "p1-1"), running(3, "p1-2"))
    assert summary.performed == {A: {"move": 2}}


async def test_what_the_last_tick_set_off_is_not_counted_whenever_it_came() -> None:
    status = keys.executor_status(A)
    upto = {keys.CLOCK: 2, ACTS: 1, status: 1}  # RunFinished.sent: before the last epoch
    last = (tick(5, 2), act(6, 2), running(2, "p1-2"))  # the last tick and what it set off
    early = await counted(tick(1, 0), tick(3, 1), act(4, 1), running(1, "p1-1"), *last, upto=upto)
    assert early.actions[A] == {"actions": 1, "first_action": 1.0}
    assert early.performed == {A: {"move": 1}}
    everything = await counted(tick(1, 0), tick(3, 1), act(4, 1), running(1, "p1-1"), *last)
    assert everything.actions[A]["actions"] == 2  # no cut: a run that did not end (failed)


async def test_the_cut_is_of_a_restarted_senders_last_life() -> None:
    """An executor restarted numbers its messages afresh: the run's end cuts its new
    life's, and what its first life sent all counts."""
    first_life = [running(n, f"p1-{n}") for n in (1, 2, 3)]
    second_life = [running(n, f"p2-{n}") for n in (1, 2)]
    upto = {keys.executor_status(A): 1}
    summary = await counted(*first_life, *second_life, upto=upto)
    assert summary.performed == {A: {"move": 4}}


async def test_the_counts_wait_for_what_the_run_says_was_sent() -> None:
    counts, counted_keys_ = RunCounts(tally.PlannerTally()), counted_keys([A])
    status = keys.executor_status(A)
    feed: asyncio.Queue[Stamped] = asyncio.Queue()

    async def arriving() -> AsyncIterator[Stamped]:
        while True:
            yield await feed.get()

    listening = asyncio.create_task(counts.listen(arriving()))
    sent = {status: 2, keys.CLOCK: 1, keys.world_stream("snapshot"): 7}  # not counted: no wait
    feed.put_nowait(tick(1, 0))
    waiting = asyncio.create_task(counts.cover(sent, counted_keys_, timeout=5))
    feed.put_nowait(running(1, "p1-1"))
    await settle()
    assert not waiting.done()
    feed.put_nowait(running(2, "p1-2"))
    assert await waiting == {}
    assert await counts.cover({status: 3}, counted_keys_, timeout=0.01) == {status: 3}
    listening.cancel()
