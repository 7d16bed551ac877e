"""The offline planner's view of execution: plan from the state the running steps leave.

An offline (plan, then act) search asked for while a plan executes (a revised goal, a new
desire) must not plan from the beliefs as they are: the robot is in the middle of a step,
and by the time the plan comes that step has ended somewhere else, so the new plan's
first step would be refused ("at start condition ... does not hold"). `Execution` keeps
the steps this planner sent as the executor runs them (with their statuses), and
`commit` gives the problem from the committed state: the beliefs with every started
step's effects applied, which is what the paper's continual
planner plans from too (`cbdi_planner.continual.commit`). The plan then follows the
last committed step (`applies_after`), from the time it ends.

A plan that comes back after execution started a step past the committed ones comes
too late: the executor refuses it (as any late replacement) and the scheduler asks again.

The beliefs are what the robot senses now: mid-step they may lack what the step needed
to start (a busy robot is not `idle`: grounded from them alone, the task would not even
hold the step) and may show part of its effects already (a battery used at its start).
So the task is grounded to reach the running steps (`held_at_start`), and what of their
effects the beliefs show already is not applied again (`Sensed`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from cbdi.beliefs import BeliefSet
from cbdi.wire.agent import ActionStatus, PlanStep
from cbdi_planner.agent.grounded import Groundings
from cbdi_planner.agent.problem import problem_from_beliefs
from cbdi_planner.agent.steps import held_at_start
from cbdi_planner.continual import Sensed, commit
from cbdi_planner.continual.execution import DONE, STARTED
from cbdi_planner.errors import Unsolvable
from cbdi_planner.grounding import ground
from cbdi_planner.pddl.ast import Domain, Problem
from cbdi_planner.plan import ScheduledAction
from cbdi_planner.task import Task

__all__ = ["Basis", "Committed", "Execution"]


@dataclass(frozen=True)
class Committed:
    """What a search plans from: `problem`, after the first `count` steps of the
    execution (the last of them `after`, "" for none), which end by `ends`."""

    problem: Problem
    count: int
    after: str
    ends: float


Basis = Callable[[], Committed]  # what a search plans from, made in its thread


@dataclass
class Execution:
    """The steps this planner sent, in the executor's order, and how each is doing."""

    steps: list[ScheduledAction] = field(default_factory=list)
    ids: list[str] = field(default_factory=list)
    statuses: dict[int, str] = field(default_factory=dict)
    began: dict[int, float] = field(default_factory=dict)  # started steps' start times

    def copy(self) -> Execution:
        """This execution as it is now (for a search's thread)."""
        return Execution(list(self.steps), list(self.ids), dict(self.statuses), dict(self.began))

    def on_status(self, status: ActionStatus) -> None:
        """Record a step's status (steps of plans no longer executing are ignored)."""
        if status.step_id in self.ids:
            k = self.ids.index(status.step_id)
            self.statuses[k] = status.status
            if status.status == "running":
                self.began[k] = status.time  # the world's start time

    def running(self) -> list[str]:
        """The ground actions of the steps that run now."""
        return [self.steps[k].name for k, st in sorted(self.statuses.items()) if st == "running"]

    def held(self, domain: Domain) -> list[tuple[str, ...]]:
        """The facts the running steps started from (`held_at_start`)."""
        return [f for name in self.running() for f in held_at_start(domain, name)]

    def follow(self, kept: int, steps: Sequence[PlanStep]) -> None:
        """A plan went out that follows the first `kept` steps: they stay, then it."""
        self.steps = self.steps[:kept]
        self.ids = self.ids[:kept]
        self.statuses = {k: s for k, s in self.statuses.items() if k < kept}
        self.began = {k: t for k, t in self.began.items() if k < kept}
        for s in sorted(steps, key=lambda st: st.start):
            name = " ".join([s.action, *s.args])
            self.steps.append(ScheduledAction(s.start, name, s.duration or None))
            self.ids.append(s.step_id)

    def commit(
        self,
        domain: Domain,
        beliefs: BeliefSet,
        goal: list[list[str]],
        sensed_at: float | None = None,
    ) -> Committed:
        """The problem of reaching `goal` from the committed state: `beliefs` with the
        started steps' effects applied, once (`sensed_at`: the beliefs' time, which
        tells what of a started step they show already: `continual.execution`). With
        nothing started, or started steps that cannot be simulated from these beliefs,
        the beliefs as they are."""
        problem = problem_from_beliefs(domain, beliefs, goal)
        as_is = Committed(problem, 0, "", 0.0)
        if not any(self.statuses.get(k) == "running" for k in range(len(self.steps))):
            return as_is
        task = self._task(domain, beliefs, goal, problem)
        finished = _leading(self.statuses, DONE)
        started = _leading(self.statuses, STARTED)
        sensed = Sensed(sensed_at, self.began) if sensed_at is not None else None
        done = commit(task, self.steps, self.statuses, started - finished, sensed)
        if done.state is None or done.count == 0:
            return as_is
        changing = set(task.facts)
        facts = {a for a in beliefs.facts if _name(a) not in changing}
        facts |= {_atom(name) for name in task.fact_names(done.state.facts)}
        fluents = {a: v for a, v in beliefs.fluents.items() if _name(a) not in task.num_vars}
        fluents |= {_atom(n): v for n, v in zip(task.num_vars, done.state.nums, strict=True)}
        after = BeliefSet(beliefs.instances, frozenset(facts), fluents)
        ends = max(a.time + (a.duration or 0.0) for a in self.steps[: done.count])
        return Committed(
            problem_from_beliefs(domain, after, goal), done.count, self.ids[done.count - 1], ends
        )

    def _task(
        self, domain: Domain, beliefs: BeliefSet, goal: list[list[str]], problem: Problem
    ) -> Task:
        """The task of `problem`, grounded to reach the running steps too: from the
        beliefs alone if they do (a grid robot mid-move), else from the beliefs and
        the facts those steps started from."""
        running = self.running()
        try:
            task = ground(domain, problem)
        except Unsolvable:
            task = None
        names = {a.name for a in task.actions} if task is not None else set()
        if task is not None and all(name in names for name in running):
            return task
        return Groundings(domain).task(beliefs, goal, self.held(domain))


def _leading(statuses: dict[int, str], kinds: tuple[str, ...]) -> int:
    """How many steps from the first on have a status among `kinds`."""
    n = 0
    while statuses.get(n) in kinds:
        n += 1
    return n


def _name(atom: tuple[str, ...]) -> str:
    return f"({' '.join(atom)})"


def _atom(name: str) -> tuple[str, ...]:
    return tuple(name[1:-1].split())
