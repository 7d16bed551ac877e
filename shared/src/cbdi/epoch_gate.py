"""The epoch gate (`EpochGate`): a component's inputs, released epoch by epoch in one
order, whatever the order they arrived in (`cbdi.lockstep` says when and why).

Pure but for the asyncio condition it waits on: what the gate releases depends only on
the messages and acks put in, never on the machine's pace.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from cbdi import keys
from cbdi.bus.typed import Stamped
from cbdi.wire.base import Message
from cbdi.wire.world import (
    ACK_STAGES,
    EpochAck,
    Percept,
)

__all__ = ["WORLD", "EpochGate", "GateResult", "Need", "default_sender", "stage_rank"]

WORLD = "world"  # the sender name of everything the world publishes


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
    released: int = -1  # the world's latest epoch a gate released
    # Counts given up on at a timeout: samples lost on the way (never to come, since
    # nothing later on their key raises the count) are not waited for again.
    given: dict[str, int] = field(default_factory=dict)
    replayed: int = -1  # a restarted world publishes its epochs up to this again: had


class EpochGate:
    """Buffer a component's inputs and release them epoch by epoch (see the module)."""

    def __init__(
        self, key_exprs: Sequence[str], sender_of: Callable[[str], str] = default_sender
    ) -> None:
        self.key_exprs = list(key_exprs)  # what this component hears
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
                s.received, s.buffer, s.given = {}, [], {}
                s.acks = {k: a for k, a in s.acks.items() if k[0] < 0}
                # A restarted world publishes its last epoch again (it cannot know
                # whether that went out before the crash): what we released is had.
                # Its percepts' counts were of the old life's keys: gone with it.
                s.replayed = s.released
                s.world_epoch, s.world_sent = -1, {}
            s.received[key] = max(s.received.get(key, 0), seq)
            if isinstance(msg, EpochAck):
                self._ack(msg)
            elif 0 <= _epoch_of(msg) <= s.replayed:
                pass  # counted as received (what follows counts it), not handled twice
            else:
                s.buffer.append(item)
                if isinstance(msg, Percept):
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
            return self._has(s, self._world_sent(need.epoch))
        ack = self._ack_for(need)
        return ack is not None and self._has(s, ack.sent)

    def _has(self, s: _Sender, counts: dict[str, int]) -> bool:
        """Whether what `counts` says was sent (on keys we hear) is here or given up."""
        return all(
            max(s.received.get(k, 0), s.given.get(k, 0)) >= n
            for k, n in counts.items()
            if self.hears(k)
        )

    def _give_up(self, need: Need) -> None:
        """A need not met in time: what its counts say is missing is taken as lost (what
        came is taken now, the rest never waited for again; a later sample on its key
        raises the count past it anyway). Without an ack there is nothing to count."""
        s = self._of(need.sender)
        if need.sender == WORLD:
            counts = self._world_sent(need.epoch) if s.world_epoch >= need.epoch else {}
        else:
            ack = self._ack_for(need)
            counts = dict(ack.sent) if ack is not None else {}
        for k, n in counts.items():
            if self.hears(k) and s.received.get(k, 0) < n:
                s.given[k] = max(s.given.get(k, 0), n)

    def _world_sent(self, epoch: int) -> dict[str, int]:
        """The `sent` of the world's percepts of `epoch` (or the earliest later ones)."""
        s = self._of(WORLD)
        later = [e for e in s.world_sent if e >= epoch]
        return s.world_sent[min(later)] if later else {}

    def hears(self, key: str) -> bool:
        """Whether this component subscribes to `key` (only those counts are waited for)."""
        try:
            return any(keys.matches(e, key) for e in self.key_exprs)
        except ValueError:
            return False  # not a key (an ack's garbage): nobody can send on it

    async def wait(self, needs: Sequence[Need], timeout: float | None) -> GateResult:
        """Wait until every need is met (or the timeout), then release what they cover."""
        result = GateResult()
        try:
            async with asyncio.timeout(timeout), self.changed:
                await self.changed.wait_for(lambda: all(self.met(n) for n in needs))
        except TimeoutError:
            result.late = [n.sender for n in needs if not self.met(n)]
            for need in needs:
                if not self.met(need):
                    self._give_up(need)
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
                    if isinstance(item.message, Percept) and item.message.epoch >= need.epoch
                ),
                len(s.buffer) if need.epoch < 0 else 0,
            )
            # And what the percepts' `sent` covers that was recovered after them.
            sent = self._world_sent(need.epoch) if need.epoch >= 0 else {}
            s.released = max(s.released, need.epoch)
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


def _epoch_of(msg: Message) -> int:
    """The epoch a world message belongs to (its tick, outcomes, percepts, snapshot all
    say it); -1 when it says none, so that it is never taken for a repeat."""
    epoch = getattr(msg, "epoch", -1)
    return epoch if isinstance(epoch, int) else -1


def _in_order(items: list[Stamped]) -> list[Stamped]:
    """Put one sender's messages in the order it sent them (several subscriptions
    deliver in no common order); unstamped ones keep their arrival order."""
    if any(not i.order for i in items):
        return items
    return sorted(items, key=lambda i: i.order)
