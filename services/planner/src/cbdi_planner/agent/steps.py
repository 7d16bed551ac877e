"""Turn a planner's time-triggered plan into steps the executor can check and dispatch.

Each step carries its action's ground conditions: `at start` ones to check before
dispatch and `over all` ones to watch while it runs (literals and comparisons of a
function with a number; other numeric conditions are left to the world).
"""

from __future__ import annotations

from collections.abc import Iterable

from cbdi.wire.agent import Check, CheckOp, PlanStep
from cbdi_planner.pddl.ast import ALL, START, Action, Compare, Cond, Domain, FHead, Lit, Num
from cbdi_planner.plan import Plan

__all__ = ["held_at_start", "plan_steps"]

_OPS: dict[str, CheckOp] = {"<": "LT", "<=": "LE", "=": "EQ", ">=": "GE", ">": "GT"}


def _ground(args: Iterable[str], binding: dict[str, str]) -> list[str]:
    return [binding.get(a, a) for a in args]


def _check(cond: Cond, binding: dict[str, str]) -> Check | None:
    if isinstance(cond, Lit):
        if cond.atom.predicate == "=":
            return None  # equality of parameters: settled when grounding
        atom = [cond.atom.predicate, *_ground(cond.atom.args, binding)]
        return Check(atom=atom, op="T" if cond.positive else "F")
    if isinstance(cond, Compare) and isinstance(cond.lhs, FHead) and isinstance(cond.rhs, Num):
        atom = [cond.lhs.name, *_ground(cond.lhs.args, binding)]
        return Check(atom=atom, op=_OPS[cond.op], value=cond.rhs.value)
    return None


def _checks(action: Action, binding: dict[str, str], when: str) -> list[Check]:
    out = []
    for cond in action.conditions:
        if getattr(cond, "time", None) == when:
            check = _check(cond, binding)
            if check is not None:
                out.append(check)
    return out


def plan_steps(domain: Domain, plan: Plan, start: float, prefix: str) -> list[PlanStep]:
    """Return the plan's actions as steps starting at `start`, ids `<prefix>-<n>`."""
    actions = {a.name: a for a in domain.actions}
    steps = []
    for i, scheduled in enumerate(plan.actions, start=1):
        name, *args = scheduled.name.split()
        action = actions[name]
        binding = {p.name: v for p, v in zip(action.params, args, strict=True)}
        steps.append(
            PlanStep(
                step_id=f"{prefix}-{i}",
                action=name,
                args=args,
                start=start + scheduled.time,
                duration=scheduled.duration or 0.0,
                at_start=_checks(action, binding, START),
                over_all=_checks(action, binding, ALL),
            )
        )
    return steps


def held_at_start(domain: Domain, name: str) -> list[tuple[str, ...]]:
    """The facts that held when the ground action `name` ("drive robot1 c_1 c_2") started:
    its positive `at start` literals (the world let it start). Beliefs sensed after it
    started may lack them (`(idle robot1)`), and a task grounded from those beliefs alone
    would not reach the action, nor anything after it."""
    action_name, *args = name.split()
    action = next((a for a in domain.actions if a.name == action_name), None)
    if action is None or len(action.params) != len(args):
        return []
    binding = {p.name: v for p, v in zip(action.params, args, strict=True)}
    return [tuple(c.atom) for c in _checks(action, binding, START) if c.op == "T"]
