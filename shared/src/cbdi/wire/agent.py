"""Wire types inside an agent: plans to execute, action status, early arrest, beliefs.

A plan is time-triggered: every step has an absolute start time (simulated seconds) and a
duration, and carries the ground conditions the executor checks before dispatching it
(`at_start`) and while it runs (`over_all`). A `PartialPlan` continues the plan named by
its `baseline` (empty: a new plan); a plan with a different baseline replaces the queue.
"""

from __future__ import annotations

from cbdi.wire.base import Message

__all__ = [
    "STEP_STATUSES",
    "ActionStatus",
    "AgentReply",
    "AgentRequest",
    "ArrestReport",
    "BeliefsUpdate",
    "Check",
    "Claim",
    "DesireEvent",
    "EarlyArrest",
    "PartialPlan",
    "PlanStep",
]

STEP_STATUSES = ("waiting", "running", "succeeded", "failed", "refused", "cancelled")


class Check(Message, frozen=True, tag="cbdi.agent.Check/1"):
    """A ground condition: `atom` (predicate or function and args) with `op`.

    `op` is `T` (the fact holds), `F` (it does not), or a numeric comparison of the
    function's value with `value`: `EQ`, `NE`, `LT`, `LE`, `GT`, `GE`.
    """

    atom: list[str]
    op: str = "T"
    value: float = 0.0


class PlanStep(Message, frozen=True, tag="cbdi.agent.PlanStep/1"):
    """One durative action of a time-triggered plan."""

    step_id: str
    action: str
    args: list[str]
    start: float
    duration: float
    at_start: list[Check] = []
    over_all: list[Check] = []


class PartialPlan(Message, frozen=True, tag="cbdi.agent.PartialPlan/1"):
    """Steps to execute: a new plan, or more of (or a repair after) the plan `baseline`.

    A plan whose baseline is not the executing plan replaces it: the executor finishes
    the executing plan up to step `applies_after` (empty: the step running now) and then
    runs this one.
    """

    agent: str
    plan_id: str
    baseline: str
    steps: list[PlanStep]
    complete: bool = False
    applies_after: str = ""


class ActionStatus(Message, frozen=True, tag="cbdi.agent.ActionStatus/1"):
    """How a plan step is doing: waiting, running, succeeded, failed, refused, cancelled."""

    agent: str
    plan_id: str
    step_id: str
    action: str
    status: str
    reason: str
    time: float


class EarlyArrest(Message, frozen=True, tag="cbdi.agent.EarlyArrest/1"):
    """Ask the executor to start nothing after `after_step` of `plan_id`."""

    agent: str
    plan_id: str
    after_step: str


class ArrestReport(Message, frozen=True, tag="cbdi.agent.ArrestReport/1"):
    """The executor stopped: every step up to `last_step` ended; nothing after started."""

    agent: str
    plan_id: str
    last_step: str
    time: float
    cancelled: list[str]


class BeliefsUpdate(Message, frozen=True, tag="cbdi.agent.BeliefsUpdate/1"):
    """The agent's whole belief set, published by the scheduler on every change."""

    agent: str
    time: float
    instances: dict[str, str]
    facts: list[list[str]]
    fluents: list[tuple[list[str], float]]
    epoch: int = -1  # the world epoch whose percepts these beliefs include


class DesireEvent(Message, frozen=True, tag="cbdi.agent.DesireEvent/1"):
    """A desire was added, boosted, reduced (goal atoms claimed by other agents), activated,
    achieved or dropped (with the reason)."""

    agent: str
    desire: str
    event: str
    reason: str
    time: float
    goal: list[list[str]] = []


class AgentRequest(Message, frozen=True, tag="cbdi.agent.AgentRequest/1"):
    """Another agent asks to check or add a belief or a desire of this agent.

    `op` is `check_belief`, `add_belief`, `check_desire` or `add_desire`; beliefs and goal
    literals are written as in agent files (`(litter_pose pla61 c_6_1)`). It is served only
    if `group` is one of this agent's allowed groups.
    """

    from_agent: str
    group: str
    op: str
    belief: str = ""
    desire: str = ""
    goal: list[str] = []
    priority: float = 0.5
    deadline: float = 0.0


class AgentReply(Message, frozen=True, tag="cbdi.agent.AgentReply/1"):
    """The answer: `accepted` (served, or refused with `reason`) and, for checks, `holds`."""

    accepted: bool
    holds: bool = False
    reason: str = ""


class Claim(Message, frozen=True, tag="cbdi.agent.Claim/1"):
    """An agent claims (or, `released`, gives up) a goal object within its group.

    The earliest claim (`epoch`), then the cheapest (`cost`: the claimer's distance to
    it), then the first agent name owns the object; the others leave it.
    """

    agent: str
    group: str
    item: str
    epoch: int = -1
    cost: float = 0.0
    released: bool = False
