"""Requests from other agents: check or add beliefs and desires, for allowed groups only."""

from __future__ import annotations

from cbdi.wire.agent import AgentReply, AgentRequest
from cbdi_scheduler.desires import NO_DEADLINE, Desire
from cbdi_scheduler.literals import LiteralSyntaxError, parse_belief
from cbdi_scheduler.mind import Mind

__all__ = ["OPS", "serve_request"]

OPS = ("check_belief", "add_belief", "check_desire", "add_desire")


def serve_request(mind: Mind, req: AgentRequest) -> AgentReply:
    """Serve one request against `mind`, or refuse it with the reason."""
    if req.group not in mind.spec.allowed_groups:
        return AgentReply(accepted=False, reason=f"group {req.group!r} is not allowed")
    if req.op not in OPS:
        return AgentReply(accepted=False, reason=f"unknown op {req.op!r} (known: {', '.join(OPS)})")
    try:
        if req.op == "check_belief":
            return AgentReply(accepted=True, holds=mind.beliefs.holds(parse_belief(req.belief)))
        if req.op == "add_belief":
            mind.beliefs = mind.beliefs.adding([parse_belief(req.belief)])
            return AgentReply(accepted=True, holds=True)
        if req.op == "check_desire":
            return AgentReply(accepted=True, holds=req.desire in mind.desires)
        goal = tuple(parse_belief(g) for g in req.goal)
    except LiteralSyntaxError as exc:
        return AgentReply(accepted=False, reason=str(exc))
    if not req.desire or not goal:
        return AgentReply(accepted=False, reason="add_desire needs a desire name and a goal")
    deadline = req.deadline if req.deadline > 0 else NO_DEADLINE
    desire = Desire(req.desire, goal, req.priority, deadline).due(mind.now)
    mind.desires.setdefault(desire.name, desire)
    return AgentReply(accepted=True, holds=True)
