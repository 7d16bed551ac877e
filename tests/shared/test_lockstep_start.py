"""The epoch gate at the start (epoch -1) and with members, from the replay work."""

from __future__ import annotations

from cbdi.bus.typed import Stamped
from cbdi.lockstep import EpochGate, Need
from cbdi.wire.agent import Claim
from cbdi.wire.world import EpochAck

CLAIMS = "cbdi/robot2/scheduler/claims"
PEER = "robot2/scheduler"


def claim(item: str, seq: int) -> Stamped:
    return Stamped(CLAIMS, seq, seq, Claim(agent="robot2", group="g", item=item, epoch=0))


def done(epoch: int, sent: int) -> Stamped:
    ack = EpochAck(agent="robot2", component="scheduler", epoch=epoch, sent={CLAIMS: sent})
    return Stamped("cbdi/robot2/scheduler/ack", 1, 0, ack)


async def test_a_members_epoch_0_waits_for_the_next_gate_however_early_it_comes() -> None:
    # A peer's claims of epoch 0 race ours: released at epoch 0, a fast peer's would be
    # seen and a slow one's not. Its epoch -1 covers nothing; its ack of 0 covers them.
    gate = EpochGate(["cbdi/*/scheduler/claims", "cbdi/*/scheduler/ack"])
    gate.members = {PEER}
    await gate.put(claim("p1", 1))
    assert (await gate.wait([Need(PEER, -1)], timeout=1)).messages == []
    await gate.put(done(0, 1))
    released = await gate.wait([Need(PEER, 0)], timeout=1)
    assert [m.item for _, m in released.messages] == ["p1"]  # type: ignore[attr-defined]


async def test_a_sender_not_in_lockstep_is_let_through_at_once() -> None:
    gate = EpochGate(["cbdi/*/scheduler/claims"])  # no members: robot2 is not one
    await gate.put(claim("p1", 1))
    released = await gate.wait([], timeout=1)  # nobody waits for a non-member's ack
    assert [m.item for _, m in released.messages] == ["p1"]  # type: ignore[attr-defined]
