"""Wire types inside an agent: plans to execute, action status, early arrest, beliefs.

A plan is time-triggered: every step has an absolute start time (simulated seconds) and a
duration, and carries the ground conditions the executor checks before dispatching it
(`at_start`) and while it runs (`over_all`). A `PartialPlan` continues the plan named by
its `baseline` (empty: a new plan); a plan with a different baseline replaces the queue.
"""

from __future__ import annotations

from typing import Annotated, Literal, get_args

import msgspec

from cbdi.wire.base import Message
from cbdi.wire.fields import (
    MAX_ITEMS,
    AgentName,
    Atom,
    Count,
    Epoch,
    Finite,
    Id,
    Many,
    NonNegative,
    Symbol,
    Text,
)

__all__ = [
    "STEP_STATUSES",
    "ActionStatus",
    "AgentReply",
    "AgentRequest",
    "AgentState",
    "ArrestReport",
    "BeliefsUpdate",
    "Check",
    "CheckOp",
    "Claim",
    "Condition",
    "DesireEvent",
    "DesireView",
    "EarlyArrest",
    "ExecutorState",
    "ExecutorStop",
    "IntentionView",
    "PartialPlan",
    "PlanStep",
    "RequestOp",
    "StateRequest",
    "StepStatus",
    "StepView",
]

StepStatus = Literal["waiting", "running", "succeeded", "failed", "refused", "cancelled"]
STEP_STATUSES: tuple[str, ...] = get_args(StepStatus)
CheckOp = Literal["T", "F", "EQ", "NE", "LT", "LE", "GT", "GE"]
RequestOp = Literal[
    "check_belief",
    "add_belief",
    "del_belief",
    "event",
    "check_desire",
    "add_desire",
    "del_desire",
    "halt",
    "resume",
]
# A condition as agent files write it: clauses (any one that holds will do) of literals
# (all must hold), e.g. `[["(carrying {self} p1)"], ["(map_loaded)"]]`.
Condition = Annotated[
    list[Annotated[list[Text], msgspec.Meta(max_length=100)]], msgspec.Meta(max_length=100)
]


class Check(Message, frozen=True, tag="cbdi.agent.Check/1"):
    """A ground condition: `atom` (predicate or function and args) with `op`.

    `op` is `T` (the fact holds), `F` (it does not), or a numeric comparison of the
    function's value with `value`: `EQ`, `NE`, `LT`, `LE`, `GT`, `GE`.
    """

    atom: Atom
    op: CheckOp = "T"
    value: Finite = 0.0


# The conditions of one step: bounded, however the plan came about.
Checks = Annotated[list[Check], msgspec.Meta(max_length=1000)]


class PlanStep(Message, frozen=True, tag="cbdi.agent.PlanStep/1"):
    """One durative action of a time-triggered plan."""

    step_id: Symbol
    action: Symbol
    args: Annotated[list[Symbol], msgspec.Meta(max_length=32)]
    start: Finite
    duration: NonNegative
    at_start: Checks = []
    over_all: Checks = []


class PartialPlan(Message, frozen=True, tag="cbdi.agent.PartialPlan/1"):
    """Steps to execute: a new plan, or more of (or a repair after) the plan `baseline`.

    A plan whose baseline is not the executing plan replaces it: the executor finishes
    the executing plan up to step `applies_after` (empty: the step running now) and then
    runs this one.

    `request_id` is the search request the plan answers and `purpose` why it was searched
    (`new`, `repair`, `revise`, `improve`; empty: not said, as before these fields): a
    counter of plans (`cbdi.tally`) then ties a plan to its request whatever order the
    two arrive in, since they come from different senders.
    """

    agent: AgentName
    plan_id: Symbol
    baseline: Id
    steps: Many[PlanStep]
    complete: bool = False
    applies_after: Id = ""
    request_id: Id = ""
    purpose: Id = ""


class ActionStatus(Message, frozen=True, tag="cbdi.agent.ActionStatus/1"):
    """How a plan step is doing: waiting, running, succeeded, failed, refused, cancelled."""

    agent: AgentName
    plan_id: Id
    step_id: Id
    action: Id
    status: StepStatus
    reason: Text
    time: Finite


class EarlyArrest(Message, frozen=True, tag="cbdi.agent.EarlyArrest/1"):
    """Ask the executor to start nothing after `after_step` of `plan_id`."""

    agent: AgentName
    plan_id: Id
    after_step: Id


class ArrestReport(Message, frozen=True, tag="cbdi.agent.ArrestReport/1"):
    """The executor stopped: every step up to `last_step` ended; nothing after started."""

    agent: AgentName
    plan_id: Id
    last_step: Id
    time: Finite
    cancelled: Many[Id]


class BeliefsUpdate(Message, frozen=True, tag="cbdi.agent.BeliefsUpdate/1"):
    """The agent's beliefs, published by the scheduler every epoch: the whole set, or
    what changed since an earlier update of the same series.

    `seq` numbers the sender's updates (1, 2, ...; 0: a whole set outside any series).
    `base` 0: `instances`, `facts` and `fluents` are the whole set. Otherwise the update
    changes the set update `base` gave: it adds (or sets) those, and removes the
    `dropped_*` ones. A receiver without update `base` waits for the next whole set
    (`cbdi.beliefs.BeliefsReceiver`).
    """

    agent: AgentName
    time: Finite
    instances: Annotated[dict[Symbol, Symbol], msgspec.Meta(max_length=MAX_ITEMS)]
    facts: Many[Atom]
    fluents: Many[tuple[Atom, Finite]]
    epoch: Epoch = -1  # the world epoch whose percepts these beliefs include
    seq: Count = 0
    base: Count = 0
    dropped_instances: Many[Symbol] = []
    dropped_facts: Many[Atom] = []
    dropped_fluents: Many[Atom] = []

    def __post_init__(self) -> None:
        if self.base and self.base >= self.seq:
            raise ValueError(f"update {self.seq} cannot change a later update ({self.base})")
        if not self.base and (self.dropped_instances or self.dropped_facts or self.dropped_fluents):
            raise ValueError("a whole belief set drops nothing (dropped_* need a base)")


class DesireEvent(Message, frozen=True, tag="cbdi.agent.DesireEvent/1"):
    """A desire was added, boosted, reduced (goal atoms claimed by other agents), activated,
    achieved or dropped (with the reason)."""

    agent: AgentName
    desire: Symbol
    event: Symbol
    reason: Text
    time: Finite
    goal: Many[Atom] = []


class AgentRequest(Message, frozen=True, tag="cbdi.agent.AgentRequest/1"):
    """Another agent, an operator or a sensor asks to check, add or remove a belief or a
    desire, or tells of an event.

    `op` is `check_belief`, `add_belief`, `del_belief`, `event`, `check_desire`,
    `add_desire`, `del_desire`, or `halt` (a safe stop: the running step ends, nothing
    more starts, every desire is kept and its deadline waits) and `resume`; beliefs, goal
    literals and condition literals are written as in agent files (`(parcel_at p1 c_6_1)`,
    `(= (battery robot1) 42.5)`, `(not (carrying {self} *))`). An `event` is a predicate
    atom the rules see in the next cycle only (`(bumped robot1)`): never a standing
    belief. `threshold`: an `add_belief` of a function value within this much of the
    believed value changes nothing (a sensor's noise). It is served only
    if `group` is one of this agent's allowed groups. `deadline` is relative to the
    time the desire is added (0: none). `epoch`: the asker's epoch, set by an agent that
    asks from a rule (`ask`, docs/agents.md): what the request changes is applied before
    the asked agent's percepts of the next epoch, so a lockstep run stays a function of
    its inputs; -1 (an operator, a sensor): at once.
    """

    from_agent: AgentName
    group: Symbol
    op: RequestOp
    belief: Text = ""
    desire: Id = ""
    goal: Annotated[list[Text], msgspec.Meta(max_length=1000)] = []
    priority: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.5
    deadline: NonNegative = 0.0
    precondition: Condition = []
    context: Condition = []
    epoch: Epoch = -1
    threshold: NonNegative = 0.0


class AgentReply(Message, frozen=True, tag="cbdi.agent.AgentReply/1"):
    """The answer: `accepted` (served, or refused with `reason`) and, for checks, `holds`."""

    accepted: bool
    holds: bool = False
    reason: Text = ""


class ExecutorStop(Message, frozen=True, tag="cbdi.agent.ExecutorStop/1"):
    """An operator's safe stop at the executor, which needs no scheduler: `stop` starts
    nothing more (the running action ends; performers are told to stop theirs),
    `resume` goes on with what waits, `state` only asks."""

    from_agent: AgentName
    op: Literal["stop", "resume", "state"]


class ExecutorState(Message, frozen=True, tag="cbdi.agent.ExecutorState/1"):
    """Whether the executor is stopped and what still runs (`running` "" : nothing)."""

    agent: AgentName
    halted: bool
    running: Id = ""
    time: Finite = 0.0


class StateRequest(Message, frozen=True, tag="cbdi.agent.StateRequest/1"):
    """Ask an agent's scheduler what it believes, desires and intends now."""

    beliefs: bool = True  # False: leave the belief set out (it can be large)


class DesireView(Message, frozen=True, tag="cbdi.agent.DesireView/1"):
    """One desire as the agent holds it: goal, priority, deadline (None: none)."""

    name: Symbol
    goal: Annotated[list[Text], msgspec.Meta(max_length=MAX_ITEMS)]
    priority: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
    deadline: NonNegative | None = None
    precondition: Condition = []
    context: Condition = []


class StepView(Message, frozen=True, tag="cbdi.agent.StepView/1"):
    """One step of the executing plan and its last reported status ("" none yet)."""

    step_id: Symbol
    action: Text  # `(move robot1 c_0_0 c_0_1)`
    start: Finite
    duration: NonNegative
    status: Id = ""


class IntentionView(Message, frozen=True, tag="cbdi.agent.IntentionView/1"):
    """The intention: the desire pursued, its plan (if any yet) and how it is going."""

    desire: Symbol
    plan_id: Id = ""
    steps: Many[StepView] = []
    waiting: bool = False  # its goal is blocked by something that moves
    stopping: bool = False  # an early arrest is under way
    # Its last search failed on this and waits for the beliefs to change ("" if not),
    # and when it is tried again (`when the beliefs change, or at t=12 if nothing does`).
    retry: Text = ""
    retry_when: Text = ""


class AgentState(Message, frozen=True, tag="cbdi.agent.AgentState/1"):
    """An agent's mind at simulated `time`: beliefs, desires, intention."""

    agent: AgentName
    time: Finite
    beliefs: Annotated[list[Text], msgspec.Meta(max_length=MAX_ITEMS)] = []
    desires: Annotated[list[DesireView], msgspec.Meta(max_length=10_000)] = []
    intention: IntentionView | None = None
    halted: bool = False  # a safe stop holds (`stopping` in the intention: not yet still)


class Claim(Message, frozen=True, tag="cbdi.agent.Claim/1"):
    """An agent claims (or, `released`, gives up) a goal object within its group.

    How claims decide is `cbdi_scheduler.claims` (docs/agents.md): claims made about the
    same time compete by `cost` (the claimer's way to the object) and the load each
    claimer already has; a later claim is a bid, which the owner answers by handing the
    object over (`released` with `to`: the bidder, whose `epoch` and `cost` the handover
    repeats) when the bidder can do it clearly sooner. `achieved`: a
    release because the claimer achieved the goal atom (`["delivered", "p1"]`, its
    second symbol the item): the group believes it, and every claim on the object ends.
    """

    agent: AgentName
    group: Symbol
    item: Symbol
    epoch: Epoch = -1
    cost: Finite = 0.0
    released: bool = False
    achieved: Annotated[list[Symbol], msgspec.Meta(max_length=32)] = []
    to: Annotated[str, msgspec.Meta(max_length=63, pattern=r"^([A-Za-z][A-Za-z0-9_\-]*)?$")] = ""

    def __post_init__(self) -> None:
        if self.achieved and not self.released:
            raise ValueError("only a release says a goal was achieved")
        if self.to and (not self.released or self.achieved or self.to == self.agent):
            raise ValueError(f"a handover to {self.to} is a release to another agent, not achieved")
        if self.achieved and (len(self.achieved) < 2 or self.achieved[1] != self.item):
            raise ValueError(f"achieved {self.achieved} is not a goal atom on item {self.item}")
