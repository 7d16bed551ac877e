"""Requests from other agents, operators and sensors: check, add or remove beliefs and
desires, tell of events, for allowed groups only; and the agent's state, for anyone who
may read it.

Every literal is read as agent files read it and checked against the domain (a
predicate the domain lacks is refused, naming it); `{self}` stands for the agent.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial

from cbdi.beliefs import PREDICATE, Belief
from cbdi.wire.agent import AgentReply, AgentRequest
from cbdi_scheduler.agentfile import undeclared
from cbdi_scheduler.conditions import Condition
from cbdi_scheduler.desires import NO_DEADLINE, Desire
from cbdi_scheduler.literals import LiteralSyntaxError, parse_belief, parse_literal
from cbdi_scheduler.mind import Mind

__all__ = ["OPS", "Served", "prepare_request", "serve_request"]

OPS = (
    "check_belief",
    "add_belief",
    "del_belief",
    "event",
    "check_desire",
    "add_desire",
    "del_desire",
    "halt",
    "resume",
)


class _Refused(Exception):
    """A request that cannot be served; the message is the reason."""


@dataclass(frozen=True)
class Served:
    """A checked request: the reply, and what it changes in the mind (None: nothing,
    a check or a refusal), to apply now or, for an agent's ask, at its epoch's end."""

    reply: AgentReply
    apply: Callable[[], None] | None = None


def serve_request(mind: Mind, req: AgentRequest) -> AgentReply:
    """Serve one request against `mind` now, or refuse it with the reason."""
    served = prepare_request(mind, req)
    if served.apply is not None:
        served.apply()
    return served.reply


def prepare_request(mind: Mind, req: AgentRequest) -> Served:
    """Check one request against `mind`: the reply, and the change it asks for."""
    if req.group not in mind.spec.allowed_groups:
        return Served(AgentReply(accepted=False, reason=f"group {req.group!r} is not allowed"))
    if req.op not in OPS:
        why = f"unknown op {req.op!r} (known: {', '.join(OPS)})"
        return Served(AgentReply(accepted=False, reason=why))
    try:
        return _serve(mind, req)
    except _Refused as exc:
        return Served(AgentReply(accepted=False, reason=str(exc)))


def _serve(mind: Mind, req: AgentRequest) -> Served:
    if req.op in ("halt", "resume"):
        stop = req.op == "halt"
        if not stop and not mind.intentions.halted and not mind.stop_asked:
            raise _Refused("not halted: nothing to resume")
        return Served(AgentReply(accepted=True, holds=stop), partial(mind.request_stop, stop))
    if req.op == "check_desire":
        return Served(AgentReply(accepted=True, holds=req.desire in mind.desires))
    if req.op == "del_desire":
        if req.desire not in mind.desires:
            held = ", ".join(sorted(mind.desires)) or "none"
            raise _Refused(f"no desire {req.desire!r} is held (held: {held})")
        why = f"removed by {req.from_agent}"
        return Served(
            AgentReply(accepted=True, holds=True), partial(mind.withdraw, req.desire, why)
        )
    if req.op != "add_desire":
        belief = _belief(mind, req.belief, "belief")
        if req.op == "check_belief":
            return Served(AgentReply(accepted=True, holds=mind.beliefs.holds(belief)))
        if req.op == "event":
            if belief.kind != PREDICATE:
                why = f"belief: an event is a predicate atom like (bumped robot1), not {belief}"
                raise _Refused(why)
            return Served(
                AgentReply(accepted=True, holds=True), partial(mind.request_event, belief)
            )
        adding = req.op == "add_belief"
        change = partial(
            mind.request_beliefs,
            [belief] if adding else [],
            [] if adding else [belief],
            req.threshold,
        )
        return Served(AgentReply(accepted=True, holds=adding), change)
    if not req.desire or not req.goal:
        raise _Refused("add_desire needs a desire name and a goal")
    if req.desire in mind.desires:
        raise _Refused(f"a desire {req.desire!r} is already held")
    goal = tuple(_belief(mind, g, f"goal[{i}]", goal=True) for i, g in enumerate(req.goal))
    deadline = req.deadline if req.deadline > 0 else NO_DEADLINE
    desire = Desire(
        req.desire,
        goal,
        req.priority,
        deadline,
        precondition=_condition(mind, req.precondition, "precondition"),
        context=_condition(mind, req.context, "context"),
    )
    return Served(AgentReply(accepted=True, holds=True), partial(_add_desire, mind, desire))


def _add_desire(mind: Mind, desire: Desire) -> None:
    mind.request_desire(desire.due(mind.now))  # its deadline runs from when it is held


def _text(mind: Mind, text: str) -> str:
    return text.replace("{self}", mind.agent)


def _belief(mind: Mind, text: str, where: str, goal: bool = False) -> Belief:
    try:
        belief = parse_belief(_text(mind, text))
    except (LiteralSyntaxError, ValueError) as exc:
        raise _Refused(f"{where}: {exc}") from None
    _check_declared(mind, belief, where, goal)
    return belief


def _check_declared(mind: Mind, belief: Belief, where: str, goal: bool = False) -> None:
    spec = mind.spec
    why = undeclared(belief, spec.signature, spec.private_predicates, goal, spec.functions)
    if why and spec.signature:  # an agent file read without its domain checks nothing
        raise _Refused(f"{where}: {why}")


def _condition(mind: Mind, clauses: Sequence[Sequence[str]], where: str) -> Condition:
    out = []
    for i, clause in enumerate(clauses):
        try:
            literals = tuple(parse_literal(_text(mind, t)) for t in clause)
        except (LiteralSyntaxError, ValueError) as exc:
            raise _Refused(f"{where}[{i}]: {exc}") from None
        for j, lit in enumerate(literals):
            _check_declared(mind, lit.belief, f"{where}[{i}][{j}]")
        out.append(literals)
    return tuple(out)
