"""The planning tasks of one agent's planner: from its beliefs and its request's goal,
or from a request's own PDDL problem; grounded once (`Groundings`), ahead of time in a
worker thread (`warm`), and whether a goal out of reach is only blocked by things that
move (a failed search says so). `ContinualPlanner` plans with them.
"""

from __future__ import annotations

import contextlib
import math

from msgspec.structs import replace

from cbdi.agentfile import PlanningSettings
from cbdi.beliefs import BeliefSet
from cbdi.wire.planner import SearchRequest, SearchStatus
from cbdi_planner.agent.grounded import Groundings, reaches_goal
from cbdi_planner.agent.lines import failure_status
from cbdi_planner.agent.problem import (
    GoalError,
    beliefs_from_problem,
    goal_of,
    problem_from_beliefs,
)
from cbdi_planner.agent.transient import Transients
from cbdi_planner.continual import RoundBound
from cbdi_planner.errors import PlannerError, Unsolvable
from cbdi_planner.expansion import prepare
from cbdi_planner.heuristic import RelaxedPlanGraph
from cbdi_planner.pddl import parse_problem
from cbdi_planner.pddl.ast import Domain
from cbdi_planner.task import Task

__all__ = ["AgentTasks"]


class AgentTasks:
    """What an agent's planner plans from: its beliefs, its request, the epoch grid
    (`ContinualPlanner` sets these; this part reads them)."""

    agent: str
    domain: Domain
    settings: PlanningSettings
    grid: float
    transients: Transients
    groundings: Groundings
    beliefs: BeliefSet
    request: SearchRequest | None
    # A request's problem `warm` read ahead: (the request, its beliefs and goal).
    _read: tuple[SearchRequest, tuple[BeliefSet, list[list[str]]]] | None

    def bound(self) -> RoundBound:
        s = self.settings
        return RoundBound(
            seconds=s.round_interval if s.round_interval > 0 else None,
            expansions=s.expansions_per_round if s.expansions_per_round > 0 else None,
            plan_size=s.plan_size_limit if s.plan_size_limit > 0 else None,
        )

    def task(self, goal: list[list[str]]) -> Task:
        """The task of reaching `goal` from the beliefs (grounded once, see `Groundings`),
        with every action of the running steps in it (see `held`)."""
        return self.groundings.task(self.beliefs, goal, self.held())

    def held(self) -> list[tuple[str, ...]]:
        """The facts the running steps started from (none here; `ContinualPlanner` knows
        its lines)."""
        return []

    def warm(self, beliefs: BeliefSet, req: SearchRequest | None = None) -> None:
        """Ground ahead (call from a worker thread) the task that `on_beliefs(beliefs)` or
        `on_request(req)` will plan with, and build its relaxed planning graph, so they
        find both built and the event loop is not held up by either (on campus-30x30 a
        grounding takes about 200 ms, a graph 100 ms); errors are left for them to
        report."""
        goal: list[list[str]] | None
        if req is not None and req.problem and req.kind != "cancel":
            try:  # a request's own problem: read here, not on the loop (campus: 100 ms)
                read = self._read_problem(req)
            except (GoalError, PlannerError):
                return
            self._read = (req, read)
            beliefs, goal = read
        else:
            goal = self.goal_of(req) if req is not None else None
            if goal is None and self.request is not None:
                goal = [list(g) for g in self.request.goal]
        if not goal:
            return
        self.transients.see(beliefs)
        with contextlib.suppress(GoalError, PlannerError):
            task = self.groundings.task(beliefs, goal, self.held())
            RelaxedPlanGraph.of(task)  # what reaches_goal uses
            prepare(task)  # what a search of it expands with

    def goal_of(self, req: SearchRequest) -> list[list[str]] | None:
        """The goal `req` makes the search aim at (a revision: the union of goals)."""
        if req.kind == "cancel":
            return None
        goal = [list(g) for g in req.goal]
        if req.kind == "revise" and self.request is not None:
            union = [list(g) for g in self.request.goal]
            return union + [g for g in goal if g not in union]
        return goal

    def request_task(self, goal: list[list[str]]) -> Task:
        """`task`, raising Unsolvable if the goal is unreachable from the beliefs even
        with deletes ignored (what grounding from the beliefs alone would say)."""
        task = self.task(goal)
        if not reaches_goal(task):
            raise Unsolvable("no action reaches the goal from these beliefs (relaxed)")
        return task

    def at_grid(self, t: float) -> float:
        """The first epoch boundary at or after `t`: when a step planned now can start
        (in lockstep the executor acts after the planner in the same epoch)."""
        return math.ceil(t / self.grid - 1e-9) * self.grid

    def on_grid(self, t: float) -> float:
        """`t` on the epoch grid, as a step's start is published (the search separates
        steps by a small epsilon that the grid rounds away)."""
        return round(t / self.grid) * self.grid

    def _with_problem(self, req: SearchRequest) -> SearchRequest:
        """Take a request's own PDDL problem as the beliefs (and goal, if it has none)."""
        if not req.problem or req.kind == "cancel":
            return req
        read, self._read = self._read, None
        beliefs, goal = read[1] if read and read[0] is req else self._read_problem(req)
        self.beliefs = beliefs
        self.transients.see(beliefs)
        return replace(req, goal=goal, problem="")

    def _read_problem(self, req: SearchRequest) -> tuple[BeliefSet, list[list[str]]]:
        """The beliefs and goal of a request's own PDDL problem (its goal if it has one)."""
        problem = parse_problem(req.problem, self.domain, f"request {req.request_id}")
        goal = [list(g) for g in req.goal] or goal_of(problem)
        beliefs = beliefs_from_problem(problem)
        problem_from_beliefs(self.domain, beliefs, goal)  # the goal fits the domain
        return beliefs, goal

    def _blocked(self, goal: list[list[str]]) -> bool:
        if not goal:
            return False
        held = self.held()  # a robot mid-step: judged from what its steps started from
        try:
            known = self.groundings.blocked(self.beliefs, goal, held)
        except (GoalError, PlannerError):
            return False
        if known is not None:
            return known
        return self.transients.blocked(self.domain, self.beliefs, goal, held)

    def _failure(
        self, request_id: str, reason: str, goal: list[list[str]], blocked: bool | None = None
    ) -> SearchStatus:
        """A failed search, `blocked` if the goal is reachable once moving things move."""
        if blocked is None:
            blocked = self._blocked(goal)
        return failure_status(self.agent, request_id, reason, blocked)
