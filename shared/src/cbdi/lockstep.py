"""Lockstep in virtual time: an epoch's inputs, released in one order (`EpochGate`).

In lockstep every component of every agent handles epoch k in a fixed sequence: the
world's tick and percepts; the scheduler's belief revision and rules (stage `beliefs`);
the planner's rounds for the epoch; the scheduler's plans to the executor; the
executor's dispatch. Each acknowledges its part with what it had sent by then
(`EpochAck.sent`, its bus's per-key counts). A component waits for its upstream's acks
before its part (`Need`), then takes exactly the messages those acks cover (sequence
number up to the count), sender by sender in the order it asked for them, each sender's
in arrival order. What a component does in epoch k so depends only on what was sent to
it, never on when it arrived or how busy the machine is.

The start barrier is epoch -1: a component announces `ready` (subscribed, waiting for
epoch 0) until it sees epoch 0, and the world starts epoch 0 once every member did. A
member's epoch -1 covers nothing: what it sends in epoch 0 (a peer's first claims, which
race ours) is taken at the next gate, however early it comes.

Resynchronisation, one rule for late, frozen and restarted members alike: a `Need` not
met within the timeout is given up for this epoch and its sender named as late; what it
sent meanwhile is taken at the next gate, and what its counts said it had sent that never
came is taken as lost, never waited for again (one lost sample costs one timeout, not
one per epoch: a key sent on once, a peer's claim, would hold every gate after). A
sender whose counts go back has restarted:
its counts start afresh, and what its earlier life sent that no ack released is dropped.
The world's percepts count the outcomes they close (`Percepts.sent`), since
the bus may recover one key's samples after another's (after a router restart). A
restarted world (it goes on from its state file) lost the acks its predecessor had:
each member sends its latest one again, the very same message, when the world's
liveliness token comes back (`announce_ready`); an ack seen twice changes no gate.
"""

from __future__ import annotations

import weakref
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass

from cbdi import keys
from cbdi.bus.base import Bus
from cbdi.bus.typed import Stamped, publish, request
from cbdi.clock import WallClock
from cbdi.epoch_gate import WORLD, EpochGate, GateResult, Need, default_sender, stage_rank
from cbdi.errors import CbdiError
from cbdi.runtime.log import Log
from cbdi.view import world_info
from cbdi.wire.base import Message
from cbdi.wire.world import (
    ClockRequest,
    EpochAck,
    Percept,
    Tick,
)

__all__ = [
    "WORLD",
    "Epoch",
    "EpochGate",
    "GateResult",
    "Lockstep",
    "Need",
    "ack",
    "announce_ready",
    "default_sender",
    "resend_latest_ack",
    "send_ack",
    "stage_rank",
]

READY_EVERY = 0.5  # wall seconds between `ready` announcements (the barrier only)
ASK_WORLD = 2.0  # wall seconds to wait for the world's info before epoch 0
MAX_SENT_KEYS = 64
# Each bus's latest ack per member, as sent: what a restarted world is told again.
_LATEST: weakref.WeakKeyDictionary[Bus, dict[str, EpochAck]] = weakref.WeakKeyDictionary()


# What a component waits for before a stage of an epoch: (epoch, stage, members) -> needs.
NeedsOf = Callable[[int, str, frozenset[str]], list[Need]]


@dataclass(frozen=True)
class Epoch:
    """One stage of one epoch, released: the inputs to take in, in order, before the
    component does its part (`Lockstep.epochs` acknowledges it when the body is done)."""

    number: int
    stage: str
    messages: list[tuple[str, Message]]
    late: list[str]


class Lockstep:
    """A component's mode, decided by the world's first tick, and its gate.

    From the first `Tick` on, in lockstep, inputs go to the gate and `start(first_epoch)`
    starts the component's epoch loop, which is `async for epoch in lockstep.epochs(...)`;
    in real time `put` hands each input back at once, to be handled in arrival order.
    """

    def __init__(
        self,
        key_exprs: Sequence[str],
        start: Callable[[int], object],
        sender_of: Callable[[str], str] = default_sender,
        keep_ticks: bool = True,
        bus: Bus | None = None,
        me: str = "",
    ) -> None:
        self.gate = EpochGate(key_exprs, sender_of)
        self.start = start
        self.bus, self.me = bus, me  # to ask the world whether `me` is in lockstep
        self.lockstep_member: bool | None = None
        self.early: list[Stamped] = []
        self.keep_ticks = keep_ticks  # a component that never waits for the world drops them
        self.on: bool | None = None

    async def learn_members(self, bus: Bus, timeout: float = 30.0) -> list[str]:
        """Ask the world who is in lockstep (its info); the gate waits for those only."""
        info = await world_info(bus, timeout)
        self.gate.members = set(info.members)
        return list(info.members)

    async def epochs(
        self,
        first: int,
        needs: NeedsOf,
        timeout: float | None,
        log: Log,
        stages: Sequence[str] = ("done",),
        members: Sequence[str] | None = None,
    ) -> AsyncIterator[Epoch]:
        """The one way through the epochs, from `first` on: for each epoch and each of
        `stages` in turn, wait until `needs(epoch, stage, members)` are met (or given up
        after `timeout`, the late senders logged), yield what they released, and once the
        body is done acknowledge that stage with what the component sent by then. The
        members are `members`, or the world's (`learn_members`)."""
        if self.bus is None or not self.me:
            raise RuntimeError("Lockstep.epochs needs the bus and the member's name")
        agent, _, component = self.me.partition("/")
        if members is None:
            members = await self.learn_members(self.bus)
        self.gate.members = set(members)
        known = frozenset(members)
        epoch = first
        while True:
            for stage in stages:
                released = await self.gate.wait(needs(epoch, stage, known), timeout)
                if released.late:
                    log.warning("upstream_late", epoch=epoch, late=",".join(released.late))
                yield Epoch(epoch, stage, released.messages, released.late)
                await send_ack(self.bus, agent, component, epoch, stage)
            epoch += 1

    def decided(self) -> bool:
        """Whether the first tick came (the start barrier is behind us)."""
        return self.on is not None

    async def put(self, item: Stamped) -> list[tuple[str, Message]]:
        """Take one input; return those to handle now (real time), else none.

        The world's first tick decides the mode. An input that comes before it (other
        senders' messages may overtake the world's) asks the world's info whether we are
        a lockstep member: then it waits for the tick in the gate; with no world to ask
        (a planner used on its own) or not a member, it is handled at once.
        """
        msg = item.message
        if self.on is None:
            if isinstance(msg, EpochAck):
                await self.gate.put(item)  # acks only matter in lockstep: keep them
                return []
            if isinstance(msg, Tick):
                return await self._decide(item, msg)
            if await self._member_of_lockstep():
                self.early.append(item)
                return []
            self.on = False
            return [*self._flush(), (item.key, msg)]
        if self.on:
            await self._say_again(msg)
            if self.keep_ticks or not isinstance(msg, Tick):
                await self.gate.put(item)
            return []
        return [(item.key, msg)]

    async def _say_again(self, msg: Message) -> None:
        """A restarted world publishes the epoch it was stopped in again: a member that
        acknowledged it already sends that ack again (the world's successor waits for
        it). Its liveliness token alone cannot tell: the new world's token may come
        before the old one's goes (a killed process's lease has yet to run out)."""
        if self.bus is None or not self.me or not isinstance(msg, (Tick, Percept)):
            return
        latest = _LATEST.get(self.bus, {}).get(self.me)
        if latest is not None and latest.epoch >= msg.epoch >= 0:
            agent, _, component = self.me.partition("/")
            await publish(self.bus, keys.epoch_ack(agent, component), latest, block=True)

    async def _decide(self, item: Stamped, tick: Tick) -> list[tuple[str, Message]]:
        self.on = tick.lockstep
        if not self.on:
            return [*self._flush(), (item.key, tick)]
        for e in [*self.early, item]:
            if self.keep_ticks or not isinstance(e.message, Tick):
                await self.gate.put(e)
        self.early = []
        # A first tick past epoch 0: the world's counts in its percepts include ticks
        # sent before we listened.
        self.gate.late_world = tick.epoch > 0
        if tick.epoch > 0:
            # A member that restarted mid-run and heard a tick before `rejoin` asked for
            # one. It may be a restarted world's repeat of an epoch whose acks went by
            # before we listened: joined as `rejoin` joins, from the next epoch.
            self.gate.joined, self.gate.rebase = tick.epoch + 1, True
        else:
            self.gate.joined = 0
        self.start(tick.epoch)
        return []

    async def rejoin(self) -> bool:
        """Join a run already under way (a member restarted mid-run): the world's latest
        tick is an epoch whose inputs went by before we subscribed, so it counts as
        before joining (`joined` is the next epoch), the component acks it at once and
        takes part from the next one; the world waits for no ack timeout. Return whether
        it joined so (False: not a lockstep member, or the run has not started)."""
        if self.on is not None or self.bus is None or not self.me:
            return False
        if not await self._member_of_lockstep():
            return False
        try:
            tick = await request(self.bus, keys.world_rpc("clock"), ClockRequest(), Tick)
        except CbdiError:  # not started (the barrier is ahead of us), or no world
            return False
        if self.on is not None or not tick.lockstep or tick.epoch < 1:
            # The world's next tick came first, or a real-time run; or epoch 0, whose
            # tick a member that started with the run may still have on its way (the
            # world waits for every member's ack of it: only a later epoch is sure to
            # have gone by without us).
            return False
        self.on = True
        for e in self.early:
            if self.keep_ticks or not isinstance(e.message, Tick):
                await self.gate.put(e)
        self.early = []
        self.gate.joined = tick.epoch + 1
        self.gate.rebase = True
        self.start(tick.epoch)
        return True

    def _flush(self) -> list[tuple[str, Message]]:
        early, self.early = self.early, []
        return [(e.key, e.message) for e in early]

    async def _member_of_lockstep(self) -> bool:
        """Whether the world says we are a lockstep member. Only the world's answer is
        kept: a world not up yet (one that starts after us) is asked again next time."""
        if self.lockstep_member is None:
            if self.bus is None or not self.me:
                self.lockstep_member = False
            else:
                try:
                    info = await world_info(self.bus, ASK_WORLD)
                except (TimeoutError, CbdiError):
                    return False  # no world (yet): on our own, in real time, for now
                self.lockstep_member = info.lockstep and self.me in info.members
        return self.lockstep_member


def ack(agent: str, component: str, epoch: int, stage: str, bus: Bus) -> EpochAck:
    """Return the ack of `epoch` at `stage` with what `bus` has sent so far."""
    # Acks and heartbeats (wall-clock, as many as the machine's pace gives) say nothing
    # of what the epoch's inputs are.
    sent = {
        k: n for k, n in sorted(bus.sent.items()) if not keys.is_ack(k) and not keys.is_heartbeat(k)
    }
    if len(sent) > MAX_SENT_KEYS:
        sent = dict(list(sent.items())[:MAX_SENT_KEYS])
    return EpochAck(agent=agent, epoch=epoch, component=component, stage=stage, sent=sent)  # type: ignore[arg-type]


async def send_ack(bus: Bus, agent: str, component: str, epoch: int, stage: str = "done") -> None:
    """Publish the ack of `epoch` at `stage` (what this component sent is in it)."""
    msg = ack(agent, component, epoch, stage, bus)
    _LATEST.setdefault(bus, {})[keys.member(agent, component)] = msg
    await publish(bus, keys.epoch_ack(agent, component), msg, block=True)


async def announce_ready(
    bus: Bus,
    agent: str,
    component: str,
    started: Callable[[], bool],
    every: float = READY_EVERY,
    lockstep: Lockstep | None = None,
) -> None:
    """Say `ready` (the start barrier, epoch -1) until `started()`: the world may come
    up after us, so one announcement could be lost. With `lockstep`, a run found under
    way (we restarted) is joined at its current epoch (`Lockstep.rejoin`). Then, for the
    rest of the run, `resend_latest_ack`."""
    clock = WallClock()
    while not started():
        await send_ack(bus, agent, component, -1, "ready")
        if lockstep is not None and await lockstep.rejoin():
            break
        await clock.sleep(every)
    await resend_latest_ack(bus, agent, component)


async def resend_latest_ack(bus: Bus, agent: str, component: str) -> None:
    """Send our latest ack again, unchanged, each time the world's token comes back after
    it went: a restarted world waits for the acks its predecessor got. (The token seen
    when we start watching is the world we know: nothing is sent for it.)"""
    member, gone = keys.member(agent, component), False
    async for event in bus.watch_alive(keys.alive(keys.service_id(WORLD))):
        latest = _LATEST.get(bus, {}).get(member)
        if event.alive and gone and latest is not None and latest.epoch >= 0:
            await publish(bus, keys.epoch_ack(agent, component), latest, block=True)
        gone = not event.alive
