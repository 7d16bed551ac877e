"""Asking other agents, the scheduler's side: a rule's ask on the wire, and the asks
another agent made of us, held until the epoch they belong to.

An ask carries the asker's epoch. The asked scheduler applies what it changes before
its percepts of the next epoch, whenever it came: in lockstep the asker waits for the
answer before it acknowledges its epoch, so the world cannot have started the next one,
and the change lands in the same epoch in every run (docs/agents.md, "Asking another
agent").
"""

from __future__ import annotations

from collections.abc import Callable

from cbdi import keys
from cbdi.bus import Bus, request
from cbdi.errors import CbdiError
from cbdi.runtime.log import Log
from cbdi.wire.agent import AgentReply, AgentRequest
from cbdi_scheduler.rules import Ask

__all__ = ["ASK_TIMEOUT", "HeldAsks", "ask_request", "send_ask"]

ASK_TIMEOUT = 2.0  # wall seconds an asked agent has to answer a rule's ask


class HeldAsks:
    """What other agents' asks change, held until the percepts of the epoch after theirs."""

    def __init__(self) -> None:
        self._held: list[tuple[int, Callable[[], None]]] = []

    def take(self, asked_in: int, now: int, apply: Callable[[], None]) -> None:
        """Hold `apply`, asked in epoch `asked_in`, unless the mind is past it (`now`):
        then apply it at once. An operator's request (-1) is applied at once."""
        if asked_in >= 0 and now <= asked_in:
            self._held.append((asked_in, apply))
        else:
            apply()

    def release(self, epoch: int) -> None:
        """Apply, in the order they came, the asks made before `epoch`."""
        due = [apply for asked, apply in self._held if asked < epoch]
        self._held = [(asked, apply) for asked, apply in self._held if asked >= epoch]
        for apply in due:
            apply()


def ask_request(agent: str, group: str, ask: Ask, epoch: int) -> AgentRequest:
    """Return the request that carries `agent`'s ask, made in `epoch`, under `group`."""
    return AgentRequest(
        from_agent=agent,
        group=group,
        op="add_belief" if ask.op == "ADD" else "del_belief",
        belief=str(ask.belief),
        epoch=max(epoch, 0),
    )


async def send_ask(bus: Bus, log: Log, req: AgentRequest, to: str) -> AgentReply | None:
    """Send `req` to agent `to` and log the answer; None when none came. A refusal or no
    answer is the asked agent's to give: nothing of the asker's depends on it."""
    try:
        key = keys.agent_request(keys.validate_name(to), req.group)
        reply = await request(bus, key, req, AgentReply, timeout=ASK_TIMEOUT)
    except (CbdiError, TimeoutError, ValueError) as exc:
        why = str(exc) or type(exc).__name__
        log.warning("ask_unanswered", agent=to, belief=req.belief, error=why)
        return None
    say = log.info if reply.accepted else log.warning
    say("ask", agent=to, op=req.op, belief=req.belief, accepted=reply.accepted, reason=reply.reason)
    return reply
