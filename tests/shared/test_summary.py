"""What `cbdi up` counts of a run (`cbdi.launcher.summary`): counts that do not hang on
the order in which two keys' messages arrive, and the wait for the last of them."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Iterable

from cbdi import keys
from cbdi.bus.typed import Stamped
from cbdi.launcher.summary import ACTS, Heard, RunSummary, count_actions, counted_keys
from cbdi.wire.agent import ActionStatus
from cbdi.wire.world import ActionRequest, Tick

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


async def counted(*samples: Stamped) -> tuple[RunSummary, Heard]:
    summary, heard = RunSummary(scenario="test"), Heard()
    await count_actions(stream(samples), summary, heard)
    return summary, heard


async def test_the_first_action_is_timed_by_the_worlds_order_not_by_arrival() -> None:
    # The world served the request (order 6) after its tick of epoch 1 (order 5): the tick
    # arriving late changes nothing; nor does a request of epoch 0 arriving after it.
    late_tick, _ = await counted(tick(1, 0), act(6, 2), tick(5, 1))
    in_order, _ = await counted(tick(1, 0), tick(5, 1), act(6, 2))
    early, heard = await counted(tick(1, 0), tick(5, 1), act(6, 2), act(3, 1))
    assert late_tick.actions[A] == in_order.actions[A] == {"actions": 1, "first_action": 1.0}
    assert early.actions[A] == {"actions": 2, "first_action": 0.0}
    assert heard.seq == {keys.CLOCK: 2, ACTS: 2}


async def test_a_step_is_performed_once_however_often_it_is_reported_running() -> None:
    summary, _ = await counted(running(1, "p1-1"), running(2, "p1-1"), running(3, "p1-2"))
    assert summary.performed == {A: {"move": 2}}


async def test_the_counts_wait_for_what_the_run_says_was_sent() -> None:
    heard, counted_keys_ = Heard(), counted_keys([A])
    status = keys.executor_status(A)
    sent = {status: 2, keys.CLOCK: 1, keys.world_stream("snapshot"): 7}  # not counted: no wait
    heard.note(keys.CLOCK, 1)
    waiting = asyncio.create_task(heard.cover(sent, counted_keys_, timeout=5))
    heard.note(status, 1)
    await asyncio.sleep(0)
    assert not waiting.done()
    heard.note(status, 2)
    assert await waiting == {}
    assert await heard.cover({status: 3}, counted_keys_, timeout=0.01) == {status: 3}
