"""Errors of the monitor's tools: a file they cannot read, a run they cannot replay."""

from __future__ import annotations

from cbdi.errors import CbdiError

__all__ = ["NoShellError", "NotReplayableError", "RecordingError", "UnknownAgentError"]


class RecordingError(CbdiError):
    """Refuse a file that is not a readable MCAP recording."""

    code = "bad_recording"


class NotReplayableError(CbdiError):
    """Refuse a recording that lacks what replaying an agent needs (lockstep ticks, the
    world's info, how the agent's services were started), saying what is missing."""

    code = "not_replayable"


class UnknownAgentError(CbdiError):
    """Refuse an agent whose planner and scheduler are not in the recording."""

    code = "unknown_agent"

    def __init__(self, path: str, agent: str, known: list[str]) -> None:
        self.agent, self.known = agent, known
        others = f"BDI agents in it: {', '.join(known)}" if known else "it holds no BDI agent"
        super().__init__(f"{path}: no planner and scheduler of agent {agent!r} ({others})")


class NoShellError(CbdiError):
    """Refuse a component no installed package can build (entry-point group `cbdi.shells`)."""

    code = "no_shell"
