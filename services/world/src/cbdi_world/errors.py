"""Errors of the world service; all are `CbdiError`s so the runtime reports them alike."""

from __future__ import annotations

from cbdi.errors import CbdiError

__all__ = ["UnknownAgentError", "WorldError"]


class WorldError(CbdiError):
    """Base class of the host's errors (bad agents list, settings, a simulator refused)."""

    code = "world_error"


class UnknownAgentError(WorldError):
    """Refuse a request that names an agent this world does not have."""

    code = "unknown_agent"

    def __init__(self, agent: str) -> None:
        self.agent = agent
        super().__init__(f"unknown agent {agent!r}")
