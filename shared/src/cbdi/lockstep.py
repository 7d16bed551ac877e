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
sent meanwhile is taken at the next gate. A sender whose counts go back has restarted:
its counts start afresh, and what its earlier life sent that no ack released is dropped.
The world's percepts count the outcomes they close (`Percepts.sent`), since
the bus may recover one key's samples after another's (after a router restart). A
restarted world (it goes on from its state file) lost the acks its predecessor had:
each member sends its latest one again, the very same message, when the world's
liveliness token comes back (`announce_ready`); an ack seen twice changes no gate.
"""

from __future__ import annotations

import asyncio
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from cbdi import keys
from cbdi.bus.base import Bus
from cbdi.bus.typed import Stamped, publish, request
from cbdi.clock import WallClock
from cbdi.errors import CbdiError
from cbdi.view import world_info
from cbdi.wire.base import Message
from cbdi.wire.world import ACK_STAGES, PERCEPTS, ClockRequest, EpochAck, Tick

__all__ = [
    "WORLD",
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

WORLD = "world"  # the sender name of everything the world publishes
READY_EVERY = 0.5  # wall seconds between `ready` announcements (the barrier only)
ASK_WORLD = 2.0  # wall seconds to wait for the world's info before epoch 0
MAX_SENT_KEYS = 64
# Each bus's latest ack per member, as sent: what a restarted world is told again.
_LATEST: weakref.WeakKeyDictionary[Bus, dict[str, EpochAck]] = weakref.WeakKeyDictionary()


def stage_rank(stage: str) -> int:
    """Return the order of a stage within an epoch (ready < beliefs < done)."""
    return ACK_STAGES.index(stage)


def default_sender(key: str) -> str:
    """Return who publishes on a concrete key: `world`, or the member `agent/component`."""
    part = keys.describe(key)
    if part["component"] == WORLD:
        return WORLD
    return keys.member(part["agent"], part["component"])


@dataclass(frozen=True, slots=True)
class Need:
    """What a gate waits for: `sender`'s ack of `epoch` at `stage` or later.

    For the world, the agent's percepts of `epoch` (the last of what the world publishes
    for an agent in an epoch; its tick and outcomes come before them). An epoch below 0
    needs nothing (the start).
    """

    sender: str
    epoch: int
    stage: str = "done"


@dataclass
class GateResult:
    """The messages an epoch's gate released (in order) and the senders that were late."""

    messages: list[tuple[str, Message]] = field(default_factory=list)
    late: list[str] = field(default_factory=list)


@dataclass
class _Sender:
    buffer: list[Stamped] = field(default_factory=list)
    received: dict[str, int] = field(default_factory=dict)  # highest seq per key
    acks: dict[tuple[int, int], EpochAck] = field(default_factory=dict)
    world_epoch: int = -1
    world_sent: dict[int, dict[str, int]] = field(default_factory=dict)  # percepts' `sent`


class EpochGate:
    """Buffer a component's inputs and release them epoch by epoch (see the module)."""

    def __init__(
        self, key_exprs: Sequence[str], sender_of: Callable[[str], str] = default_sender
    ) -> None:
        self.key_exprs = [e.split("/") for e in key_exprs]  # what this component hears
        self.sender_of = sender_of
        self.senders: dict[str, _Sender] = {}
        self.changed = asyncio.Condition()
        # The world's lockstep members: what others send is let through at every gate.
        self.members: set[str] = set()
        # The first epoch this component takes part in (a restarted one joins late): acks
        # of epochs before it went out before it listened, so they are not waited for.
        self.joined = 0
        # A late join (`Lockstep.rejoin`): what each sender counted in its acks before we
        # listened is gone for good, so its first ack we see is taken as received
        # (otherwise a key it sent on before, and not since, would be waited for).
        self.rebase = False
        self.late_world = False  # the same for the world only (a first tick past epoch 0)
        self.based: set[str] = set()

    def _of(self, sender: str) -> _Sender:
        return self.senders.setdefault(sender, _Sender())

    async def put(self, item: Stamped) -> None:
        """Take in one input (an ack, or a message from a sender)."""
        key, seq, msg = item.key, item.seq, item.message
        async with self.changed:
            if isinstance(msg, EpochAck):
                s = self._of(keys.member(msg.agent, msg.component))
            else:
                s = self._of(self.sender_of(key))
            if seq and seq < s.received.get(key, 0):
                # The sender restarted (on any of its keys, its acks' too: the new life's
                # first ack may come before or after its first message): its counts start
                # afresh, and what its last life sent that no ack released is dropped (a
                # new count would release it among the new life's messages: a belief
                # update of the old series applied to the new one), its acks too.
                s.received, s.buffer = {}, []
                s.acks = {k: a for k, a in s.acks.items() if k[0] < 0}
            s.received[key] = max(s.received.get(key, 0), seq)
            if isinstance(msg, EpochAck):
                self._ack(msg)
            else:
                s.buffer.append(item)
                if isinstance(msg, PERCEPTS):
                    if (self.rebase or self.late_world) and WORLD not in self.based:
                        self.based.add(WORLD)  # a late join: what it counted before is gone
                        for k, n in msg.sent.items():
                            s.received[k] = max(s.received.get(k, 0), n)
                    s.world_epoch = max(s.world_epoch, msg.epoch)
                    s.world_sent.setdefault(msg.epoch, dict(msg.sent))
                    for old in [e for e in s.world_sent if e < msg.epoch - 2]:
                        del s.world_sent[old]
            self.changed.notify_all()

    def _ack(self, msg: EpochAck) -> None:
        sender = keys.member(msg.agent, msg.component)
        s = self._of(sender)
        if self.rebase and sender not in self.based and msg.epoch >= 0:
            self.based.add(sender)
            for k, n in msg.sent.items():
                s.received[k] = max(s.received.get(k, 0), n)
        s.acks[(msg.epoch, stage_rank(msg.stage))] = msg
        for old in [k for k in s.acks if k[0] < msg.epoch - 2]:
            del s.acks[old]

    def _ack_for(self, need: Need) -> EpochAck | None:
        """The sender's ack meeting `need`: the exact one, else the earliest later one."""
        s = self._of(need.sender)
        wanted = (need.epoch, stage_rank(need.stage))
        found = [k for k in s.acks if k >= wanted]
        return s.acks[min(found)] if found else None

    def met(self, need: Need) -> bool:
        """Whether `need` is met: its ack (or world percepts) and all it covers are here."""
        if need.epoch < 0 or need.epoch < self.joined:
            return True
        s = self._of(need.sender)
        if need.sender == WORLD:
            if s.world_epoch < need.epoch:
                return False
            sent = self._world_sent(need.epoch)
            return all(s.received.get(k, 0) >= n for k, n in sent.items() if self.hears(k))
        ack = self._ack_for(need)
        if ack is None:
            return False
        return all(s.received.get(k, 0) >= n for k, n in ack.sent.items() if self.hears(k))

    def _world_sent(self, epoch: int) -> dict[str, int]:
        """The `sent` of the world's percepts of `epoch` (or the earliest later ones)."""
        s = self._of(WORLD)
        later = [e for e in s.world_sent if e >= epoch]
        return s.world_sent[min(later)] if later else {}

    def hears(self, key: str) -> bool:
        """Whether this component subscribes to `key` (only those counts are waited for)."""
        chunks = key.split("/")
        return any(_matches(e, chunks) for e in self.key_exprs)

    async def wait(self, needs: Sequence[Need], timeout: float | None) -> GateResult:
        """Wait until every need is met (or the timeout), then release what they cover."""
        result = GateResult()
        try:
            async with asyncio.timeout(timeout), self.changed:
                await self.changed.wait_for(lambda: all(self.met(n) for n in needs))
        except TimeoutError:
            result.late = [n.sender for n in needs if not self.met(n)]
        async with self.changed:
            for need in needs:
                result.messages += self._take(need)
            needed = {n.sender for n in needs}
            for sender in sorted(self.senders):  # not in lockstep: no ack to wait for
                if sender != WORLD and sender not in needed and sender not in self.members:
                    result.messages += self._take_all(sender)
        return result

    def _take(self, need: Need) -> list[tuple[str, Message]]:
        s = self._of(need.sender)
        if need.sender == WORLD:
            cut = next(
                (
                    i + 1
                    for i, item in enumerate(s.buffer)
                    if isinstance(item.message, PERCEPTS) and item.message.epoch >= need.epoch
                ),
                len(s.buffer) if need.epoch < 0 else 0,
            )
            # And what the percepts' `sent` covers that was recovered after them.
            sent = self._world_sent(need.epoch) if need.epoch >= 0 else {}
            head = s.buffer[:cut]
            after = s.buffer[cut:]
            covered = [i.seq and i.seq <= sent.get(i.key, 0) for i in after]
            rest = [i for i, c in zip(after, covered, strict=True) if c]
            s.buffer = [i for i, c in zip(after, covered, strict=True) if not c]
            return [(i.key, i.message) for i in _in_order(head + rest)]
        if need.epoch < 0:  # the start: only what came before its `ready` (nothing, usually)
            ready = s.acks.get((-1, stage_rank("ready")))
            limit: dict[str, int] | None = dict(ready.sent) if ready is not None else {}
        else:
            ack = self._ack_for(need)
            limit = ack.sent if ack is not None else None  # late: take what is here
        taken: list[Stamped] = []
        kept: list[Stamped] = []
        for item in s.buffer:
            if limit is None or not item.seq or item.seq <= limit.get(item.key, 0):
                taken.append(item)
            else:
                kept.append(item)  # sent after that ack: a later gate's
        s.buffer = kept
        return [(i.key, i.message) for i in _in_order(taken)]

    def _take_all(self, sender: str) -> list[tuple[str, Message]]:
        """Everything buffered from a sender that is not in lockstep (no ack to wait for)."""
        s = self._of(sender)
        taken, s.buffer = s.buffer, []
        return [(i.key, i.message) for i in _in_order(taken)]


def _in_order(items: list[Stamped]) -> list[Stamped]:
    """Put one sender's messages in the order it sent them (several subscriptions
    deliver in no common order); unstamped ones keep their arrival order."""
    if any(not i.order for i in items):
        return items
    return sorted(items, key=lambda i: i.order)


def _matches(expr: list[str], key: list[str]) -> bool:
    """Match key chunks against a key expression's (`*` one chunk, `**` any number)."""
    if not expr:
        return not key
    if expr[0] == "**":
        return any(_matches(expr[1:], key[i:]) for i in range(len(key) + 1))
    if not key:
        return False
    return (expr[0] == "*" or expr[0] == key[0]) and _matches(expr[1:], key[1:])


class Lockstep:
    """A component's mode, decided by the world's first tick, and its gate.

    From the first `Tick` on, in lockstep, inputs go to the gate and `start(first_epoch)`
    starts the component's epoch loop; in real time `put` hands each input back at once,
    to be handled in arrival order as before.
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
            if self.keep_ticks or not isinstance(msg, Tick):
                await self.gate.put(item)
            return []
        return [(item.key, msg)]

    async def _decide(self, item: Stamped, tick: Tick) -> list[tuple[str, Message]]:
        self.on = tick.lockstep
        if not self.on:
            return [*self._flush(), (item.key, tick)]
        for e in [*self.early, item]:
            if self.keep_ticks or not isinstance(e.message, Tick):
                await self.gate.put(e)
        self.early = []
        self.gate.joined = tick.epoch
        # A first tick past epoch 0: the world's counts in its percepts include ticks
        # sent before we listened (other senders' acks count only what we can have).
        self.gate.late_world = tick.epoch > 0
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
        if self.lockstep_member is None:
            if self.bus is None or not self.me:
                self.lockstep_member = False
            else:
                try:
                    info = await world_info(self.bus, ASK_WORLD)
                except (TimeoutError, CbdiError):
                    self.lockstep_member = False  # no world: on our own, in real time
                else:
                    self.lockstep_member = info.lockstep and self.me in info.members
        return self.lockstep_member


def ack(agent: str, component: str, epoch: int, stage: str, bus: Bus) -> EpochAck:
    """Return the ack of `epoch` at `stage` with what `bus` has sent so far."""
    # Acks and heartbeats (wall-clock, as many as the machine's pace gives) say nothing
    # of what the epoch's inputs are.
    sent = {
        k: n
        for k, n in sorted(bus.sent.items())
        if not k.endswith("/ack") and not keys.is_heartbeat(k)
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
