"""Bad input the planner service survives: reported on `cbdi/<agent>/planner/errors`.

Each is a `CbdiError` with a `code`, so the runtime logs, counts and publishes it as an
`ErrorReport` like any other service's bad input; the service goes on serving.
"""

from __future__ import annotations

from cbdi.errors import CbdiError

__all__ = ["BadRequestError", "UnknownAgentError", "UnknownPlanError"]


class BadRequestError(CbdiError):
    """A search request the planner cannot take: its problem does not parse, its goal
    names a predicate the domain does not have, or nothing can be planned from it."""

    code = "bad_request"

    def __init__(self, request_id: str, reason: str) -> None:
        self.request_id = request_id
        self.reason = reason
        super().__init__(f"search request {request_id!r}: {reason}")


class UnknownPlanError(CbdiError):
    """A step status for a plan this planner never published."""

    code = "unknown_plan"

    def __init__(self, plan_id: str, step_id: str) -> None:
        self.plan_id = plan_id
        self.step_id = step_id
        super().__init__(
            f"status of step {step_id!r} of plan {plan_id!r}, which this planner never published"
        )


class UnknownAgentError(CbdiError):
    """A message on this agent's keys that names another agent."""

    code = "unknown_agent"

    def __init__(self, agent: str, expected: str, schema: str) -> None:
        self.agent = agent
        super().__init__(f"{schema} names agent {agent!r}; this planner serves {expected!r}")
