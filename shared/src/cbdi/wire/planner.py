"""Wire types between an agent's scheduler and its planner."""

from __future__ import annotations

from typing import Annotated, Literal, get_args

import msgspec

from cbdi.wire.base import Message
from cbdi.wire.fields import AgentName, Atom, Count, Finite, Id, Problem, Symbol, Text

__all__ = [
    "FORECAST_KINDS",
    "SEARCH_KINDS",
    "SEARCH_STATUSES",
    "ForecastReport",
    "SearchKind",
    "SearchRequest",
    "SearchRound",
    "SearchStatus",
]

SearchKind = Literal["start", "revise", "cancel"]
SEARCH_KINDS: tuple[str, ...] = get_args(SearchKind)
# Reports the planner sends (status, forecast kind) are bounded names; a receiver acts
# only on the values it knows ("failed", "fails_in_committed"), so others are inert.
SEARCH_STATUSES = ("searching", "failed", "done", "cancelled")
FORECAST_KINDS = ("fails_in_committed", "fails_after_committed", "holds")


class SearchRequest(Message, frozen=True, tag="cbdi.planner.SearchRequest/1"):
    """Start a search for `goal` from the agent's current beliefs, revise its goal, or cancel.

    `goal` holds ground atoms (`["delivered", "p1"]`) that must all hold at the end.
    `problem`, if given, is a PDDL problem over the agent's domain: its objects and initial
    state replace the agent's beliefs (until the next belief update), and its goal is the
    goal when `goal` is empty. It lets a user drive one planner service directly.
    `beliefs`: the `seq` of the sender's latest `BeliefsUpdate` when it asked (0: none
    said); the planner searches from those beliefs or later ones, never earlier ones (in
    real time the request may overtake them: they travel on another key).
    """

    agent: AgentName
    request_id: Symbol
    kind: SearchKind
    desire: Id = ""
    goal: Annotated[list[Atom], msgspec.Meta(max_length=10_000)] = []
    problem: Problem = ""
    beliefs: Count = 0


class SearchStatus(Message, frozen=True, tag="cbdi.planner.SearchStatus/1"):
    """How the planner's search for `request_id` is going.

    A `failed` search is `blocked` when the goal would be reachable if the beliefs the
    agent file declares transient (`transient_predicates`: a cell `free` of people) were
    as they have been seen before: something that moves is in the way, so the scheduler
    waits for it to move instead of giving the desire up.
    """

    agent: AgentName
    request_id: Id
    status: Symbol
    reason: Text = ""
    blocked: bool = False


class SearchRound(Message, frozen=True, tag="cbdi.planner.SearchRound/1"):
    """Statistics of one round of the continual search (Alg. 1) for `plan_id`.

    `kind`: `goal`, `best` or `exhausted`; `mode`: `G` (greedy), `NG` (complete)
    or `improve` (the anytime improving search);
    `purpose`: `new`, `repair`, `revise` or `improve`; `best_h` the heuristic value of
    the best state; `plan_actions` how many actions its plan adds.
    """

    agent: AgentName
    request_id: Id
    plan_id: Id
    purpose: Id
    number: Count
    kind: Id
    mode: Id
    expanded: Count
    seconds: Finite
    best_h: int
    plan_actions: Count
    time: Finite


class ForecastReport(Message, frozen=True, tag="cbdi.planner.ForecastReport/1"):
    """The failure forecast of the executing plan: `kind` is one of FORECAST_KINDS;
    `failed_step` the step that would fail, `committed` the last committed step."""

    agent: AgentName
    plan_id: Id
    kind: Symbol
    failed_step: Id
    reason: Text
    committed: Id
    time: Finite
