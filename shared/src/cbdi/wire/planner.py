"""Wire types between an agent's scheduler and its planner."""

from __future__ import annotations

from cbdi.wire.base import Message

__all__ = [
    "FORECAST_KINDS",
    "SEARCH_KINDS",
    "SEARCH_STATUSES",
    "ForecastReport",
    "SearchRequest",
    "SearchRound",
    "SearchStatus",
]

SEARCH_KINDS = ("start", "revise", "cancel")
SEARCH_STATUSES = ("searching", "failed", "done", "cancelled")
FORECAST_KINDS = ("fails_in_committed", "fails_after_committed", "holds")


class SearchRequest(Message, frozen=True, tag="cbdi.planner.SearchRequest/1"):
    """Start a search for `goal` from the agent's current beliefs, revise its goal, or cancel.

    `goal` holds ground atoms (`["recycled", "pla61"]`) that must all hold at the end.
    `problem`, if given, is a PDDL problem over the agent's domain: its objects and initial
    state replace the agent's beliefs (until the next belief update), and its goal is the
    goal when `goal` is empty. It lets a user drive one planner service directly.
    """

    agent: str
    request_id: str
    kind: str
    desire: str = ""
    goal: list[list[str]] = []
    problem: str = ""


class SearchStatus(Message, frozen=True, tag="cbdi.planner.SearchStatus/1"):
    """How the planner's search for `request_id` is going."""

    agent: str
    request_id: str
    status: str
    reason: str = ""


class SearchRound(Message, frozen=True, tag="cbdi.planner.SearchRound/1"):
    """Statistics of one round of the continual search (Alg. 1) for `plan_id`.

    `kind`: `goal`, `best` or `exhausted`; `mode`: `G` (greedy), `NG` (complete)
    or `improve` (the anytime improving search);
    `purpose`: `new`, `repair`, `revise` or `improve`; `best_h` the heuristic value of
    the best state; `plan_actions` how many actions its plan adds.
    """

    agent: str
    request_id: str
    plan_id: str
    purpose: str
    number: int
    kind: str
    mode: str
    expanded: int
    seconds: float
    best_h: int
    plan_actions: int
    time: float


class ForecastReport(Message, frozen=True, tag="cbdi.planner.ForecastReport/1"):
    """The failure forecast of the executing plan: `kind` is one of FORECAST_KINDS;
    `failed_step` the step that would fail, `committed` the last committed step."""

    agent: str
    plan_id: str
    kind: str
    failed_step: str
    reason: str
    committed: str
    time: float
