"""Errors of the recycling grid world; all are `CbdiError`s so the host reports them alike."""

from __future__ import annotations

from cbdi.errors import CbdiError

__all__ = ["GridError", "MapError", "UnknownAgentError"]


class GridError(CbdiError):
    """Reject an impossible setup of the grid world (agents, options, a generated map)."""

    code = "world_error"


class MapError(GridError):
    """Reject a map file, naming the file, the field and the reason."""

    code = "bad_map"

    def __init__(self, path: str, field: str, reason: str) -> None:
        self.path = path
        self.field = field
        self.reason = reason
        super().__init__(f"{path}: {field}: {reason}")


class UnknownAgentError(GridError):
    """Refuse a request that names an agent this world does not have."""

    code = "unknown_agent"

    def __init__(self, agent: str) -> None:
        self.agent = agent
        super().__init__(f"unknown agent {agent!r}")
