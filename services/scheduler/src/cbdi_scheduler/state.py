"""What an operator sees of an agent: its beliefs, desires, intention and plan, now.

`PlanLog` keeps the steps the scheduler passed to its executor and the last status
reported for each, so the state shows the executing plan however it was put together
(parts, repairs, improvements).
"""

from __future__ import annotations

import math

from cbdi.wire.agent import (
    ActionStatus,
    AgentState,
    DesireView,
    IntentionView,
    PartialPlan,
    PlanStep,
    StepView,
)
from cbdi_scheduler.conditions import Condition, Literal
from cbdi_scheduler.desires import Desire
from cbdi_scheduler.mind import Mind

__all__ = ["PlanLog", "agent_state"]

_KEEP = 10_000  # steps remembered before those of past intentions are forgotten


class PlanLog:
    """The steps passed to the executor and their last reported status."""

    def __init__(self) -> None:
        self.steps: dict[str, PlanStep] = {}
        self.status: dict[str, str] = {}

    def sent(self, plan: PartialPlan, keep: list[str]) -> None:
        """Remember `plan`'s steps; past `_KEEP` steps, keep only those listed in `keep`."""
        if len(self.steps) + len(plan.steps) > _KEEP:
            wanted = set(keep)
            self.steps = {k: v for k, v in self.steps.items() if k in wanted}
            self.status = {k: v for k, v in self.status.items() if k in wanted}
        for step in plan.steps:
            self.steps[step.step_id] = step
            self.status.pop(step.step_id, None)

    def reported(self, status: ActionStatus) -> None:
        if status.step_id in self.steps:
            self.status[status.step_id] = status.status


def _condition(condition: Condition) -> list[list[str]]:
    return [[_literal_text(lit) for lit in clause] for clause in condition]


def _literal_text(lit: Literal) -> str:
    check, belief, value = lit.check, lit.belief, lit.value
    atom = f"({' '.join(belief.atom)})"
    if check == "T":
        return atom
    if check == "F":
        return f"(not {atom})"
    if check == "EX":
        return f"(exists {belief.name} - {belief.type})"
    symbol = {"EQ": "=", "NE": "!=", "LT": "<", "LE": "<=", "GT": ">", "GE": ">="}[check]
    return f"({symbol} {atom} {value:g})"


def _desire(d: Desire) -> DesireView:
    return DesireView(
        name=d.name,
        goal=[str(g) for g in d.goal],
        priority=d.priority,
        deadline=d.deadline if math.isfinite(d.deadline) else None,
        precondition=_condition(d.precondition),
        context=_condition(d.context),
    )


def _step(step: PlanStep, status: str) -> StepView:
    return StepView(
        step_id=step.step_id,
        action=f"({' '.join([step.action, *step.args])})",
        start=step.start,
        duration=step.duration,
        status=status,
    )


def agent_state(mind: Mind, log: PlanLog, beliefs: bool = True) -> AgentState:
    """Return what `mind` believes, desires and intends now (beliefs sorted by text)."""
    cur = mind.intentions.current
    intention = None
    if cur is not None:
        steps = [_step(log.steps[s], log.status.get(s, "")) for s in cur.steps if s in log.steps]
        intention = IntentionView(
            desire=cur.desire.name,
            plan_id=cur.plan_id,
            steps=steps,
            waiting=cur.waiting,
            stopping=mind.intentions.stopping,
            retry=mind.intentions.retry_reason,
            retry_when=mind.intentions.retry_when(),
        )
    return AgentState(
        agent=mind.agent,
        time=mind.now,
        beliefs=sorted(str(b) for b in mind.beliefs.beliefs()) if beliefs else [],
        desires=[_desire(d) for _, d in sorted(mind.desires.items())],
        intention=intention,
        halted=mind.intentions.halted,
    )
