"""Wire types between an agent's scheduler and its planner."""

from __future__ import annotations

from cbdi.wire.base import Message

__all__ = ["SEARCH_KINDS", "SEARCH_STATUSES", "SearchRequest", "SearchStatus"]

SEARCH_KINDS = ("start", "revise", "cancel")
SEARCH_STATUSES = ("searching", "failed", "done", "cancelled")


class SearchRequest(Message, frozen=True, tag="cbdi.planner.SearchRequest/1"):
    """Start a search for `goal` from the agent's current beliefs, revise its goal, or cancel.

    `goal` holds ground atoms (`["recycled", "pla61"]`) that must all hold at the end.
    """

    agent: str
    request_id: str
    kind: str
    desire: str = ""
    goal: list[list[str]] = []


class SearchStatus(Message, frozen=True, tag="cbdi.planner.SearchStatus/1"):
    """How the planner's search for `request_id` is going."""

    agent: str
    request_id: str
    status: str
    reason: str = ""
