"""Who the world waits for in lockstep, and how long (`AckTracker`).

Members are `agent/component` names (`robot1/planner`). The start barrier waits for
every member's `ready` (epoch -1); each later epoch waits for every member's `done`.

Resynchronisation (the rule of `cbdi.lockstep`): a member that misses the timeout is
named, its stall counted, and it is not waited for again until it acknowledges an epoch
at least as recent as the one it missed, so a dead or frozen member costs one timeout,
not one per epoch; once it catches up it is waited for again.
"""

from __future__ import annotations

import asyncio
from collections import Counter
from collections.abc import Sequence

from cbdi import keys
from cbdi.lockstep import stage_rank
from cbdi.wire.world import EpochAck
from cbdi_world.errors import WorldError

__all__ = ["AckTracker", "members_of"]


def members_of(entries: Sequence[str], agents: Sequence[str]) -> list[str]:
    """Return the lockstep members: `entries` (checked), or each agent's executor."""
    if not entries:
        return [keys.member(a, "executor") for a in agents]
    members: list[str] = []
    for entry in entries:
        agent, _, component = entry.partition("/")
        if agent not in agents:
            raise WorldError(f"--member {entry!r}: no agent {agent!r} in this world")
        try:
            keys.validate_name(component, "component")
        except ValueError as exc:
            raise WorldError(f"--member {entry!r}: {exc}") from None
        if entry not in members:
            members.append(entry)
    return members


class AckTracker:
    """The latest (epoch, stage) each member acknowledged, and the stalls."""

    def __init__(self, members: Sequence[str]) -> None:
        self.members = list(members)
        self.acked: dict[str, tuple[int, int]] = {m: (-2, 0) for m in members}
        self.behind: dict[str, int] = {}  # member -> the epoch it missed
        self.stalls: Counter[str] = Counter()
        self.sent: dict[str, dict[str, int]] = {}  # member -> its latest ack's counts
        self.changed = asyncio.Condition()

    async def observe(self, ack: EpochAck) -> None:
        """Record an ack; members the world does not wait for are ignored."""
        member = keys.member(ack.agent, ack.component)
        if member not in self.acked:
            return
        async with self.changed:
            mark = (ack.epoch, stage_rank(ack.stage))
            if mark >= self.acked[member]:
                self.sent[member] = dict(ack.sent)
            self.acked[member] = max(self.acked[member], mark)
            missed = self.behind.get(member)
            if missed is not None and ack.epoch >= missed:
                del self.behind[member]  # caught up: waited for again
            self.changed.notify_all()

    def published(self) -> dict[str, int]:
        """Return what the members' latest acks say they had sent, per key."""
        out: dict[str, int] = {}
        for counts in self.sent.values():
            for key, n in counts.items():
                out[key] = max(out.get(key, 0), n)
        return out

    def waiting_for(self, epoch: int, stage: str) -> list[str]:
        """Members (not behind) that have not acknowledged `epoch` at `stage` yet."""
        wanted = (epoch, stage_rank(stage))
        return [m for m in self.members if m not in self.behind and self.acked[m] < wanted]

    async def wait(self, epoch: int, stage: str, timeout: float) -> list[str]:
        """Wait for every member's ack of `epoch`; return (and mark behind) the late ones."""
        try:
            async with asyncio.timeout(timeout if timeout > 0 else None), self.changed:
                await self.changed.wait_for(lambda: not self.waiting_for(epoch, stage))
            return []
        except TimeoutError:
            late = self.waiting_for(epoch, stage)
            for m in late:
                self.behind[m] = epoch
                self.stalls[m] += 1
            return late
