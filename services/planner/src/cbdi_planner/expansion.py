"""Search nodes and their successors: one happening appended to a partial plan.

A node couples a state with the timeline (STN) of the plan that reached it. A
successor exists only if the happening is applicable in the state, breaks no running
invariant and leaves the timeline consistent.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from cbdi_planner.heuristic import INFINITE, RelaxedPlanGraph
from cbdi_planner.state import State, apply_end, apply_start, apply_til
from cbdi_planner.stn import END, INST, START, TIL, Future, Step, Timeline
from cbdi_planner.task import Snap, Task

__all__ = ["Expander", "Node"]


@dataclass(frozen=True, slots=True)
class Node:
    """A search node; `running` pairs each running action with its start step."""

    state: State
    timeline: Timeline
    running: tuple[tuple[int, int], ...]
    h: int
    helpful: frozenset[tuple[int, int]]
    h_time: float = 0.0

    @property
    def makespan(self) -> float:
        """Return the makespan of the partial plan so far."""
        return self.timeline.makespan


class Expander:
    """Generate and evaluate successors; counts what it does in `generated`/`evaluated`."""

    def __init__(self, task: Task, epsilon: float, compress: bool = False) -> None:
        self.task = task
        self.epsilon = epsilon
        self.compress = compress
        self.rpg = RelaxedPlanGraph(task)
        self.generated = 0
        self.evaluated = 0
        self.inconsistent = 0
        # Each action under the lowest fact of its start condition (-1: none), so
        # `successors` looks only at actions whose condition can hold in a state.
        self._by_fact: dict[int, list[int]] = {}
        for action in task.actions:
            pre = action.start.pre
            low = (pre & -pre).bit_length() - 1
            self._by_fact.setdefault(low, []).append(action.index)
        self._til_snaps = [
            Snap(0, 0, (), t.add, t.dele, (), (), 0, t.add | t.dele, 0, 0) for t in task.tils
        ]

    def root(self, state: State) -> Node:
        """Return the node of `state` with an empty plan (no running actions allowed)."""
        if state.open:
            raise ValueError("a search root cannot have running actions")
        estimate = self.rpg.estimate(state)
        self.evaluated += 1
        return Node(
            state,
            Timeline(epsilon=self.epsilon),
            (),
            estimate.value,
            estimate.helpful,
            estimate.duration,
        )

    def evaluate(
        self, state: State, timeline: Timeline, running: tuple[tuple[int, int], ...]
    ) -> Node:
        """Build a node, computing its heuristic value."""
        estimate = self.rpg.estimate(state)
        self.evaluated += 1
        return Node(state, timeline, running, estimate.value, estimate.helpful, estimate.duration)

    def successors(
        self, node: Node, helpful_only: bool = False
    ) -> Iterator[tuple[State, Timeline, tuple[tuple[int, int], ...]]]:
        """Yield the consistent successors (ends and the next timed literal first)."""
        state, timeline, task = node.state, node.timeline, self.task
        for index, start_step in node.running:
            action = task.actions[index]
            assert action.end is not None
            new = apply_end(task, state, action)
            if new is None:
                continue
            begun = timeline.steps[start_step]
            step = Step(END, index, action.end, start_step, begun.low, begun.high)
            running = tuple(r for r in node.running if r[0] != index)
            yield from self._extend(new, timeline, step, running)
        if state.til < len(task.tils):
            new = apply_til(task, state)
            if new is not None:
                when = task.tils[state.til].time
                step = Step(TIL, state.til, self._til_snaps[state.til], -1, when, when)
                yield from self._extend(new, timeline, step, node.running)
        facts = state.facts
        for index in self._candidates(node, helpful_only):
            action = task.actions[index]
            if action.start.pre & ~facts:
                continue
            kind = INST if action.end is None else START
            new = apply_start(task, state, action)
            if new is None:
                continue
            if kind == INST:
                yield from self._extend(
                    new, timeline, Step(INST, action.index, action.start), node.running
                )
                continue
            low, high = action.duration_bounds(state.nums, self.epsilon)
            if low > high or high <= 0:
                continue
            step = Step(START, action.index, action.start, -1, low, high)
            running = (*node.running, (action.index, len(timeline.steps)))
            if self.compress:
                yield from self._whole(new, timeline, step, tuple(sorted(running)))
            else:
                yield from self._extend(new, timeline, step, tuple(sorted(running)))

    def _whole(
        self, state: State, timeline: Timeline, step: Step, running: tuple[tuple[int, int], ...]
    ) -> Iterator[tuple[State, Timeline, tuple[tuple[int, int], ...]]]:
        """Append a start and, at once, its end: the action as one compressed happening.

        The state passes through the start's effects (its end condition and invariant
        are checked there, as a sequential execution would); the timeline still lifts
        the two steps into a partial order, so later actions may overlap this one.
        """
        action = self.task.actions[step.action]
        assert action.end is not None
        for started, begun, _ in self._extend(state, timeline, step, running):
            ended = apply_end(self.task, started, action)
            if ended is None:
                return
            rest = tuple(r for r in running if r[0] != step.action)
            end = Step(END, step.action, action.end, len(timeline.steps), step.low, step.high)
            yield from self._extend(ended, begun, end, rest)

    def _candidates(self, node: Node, helpful_only: bool) -> list[int]:
        """Return, in index order, the actions that may start in `node` (helpful ones)."""
        if helpful_only:
            return sorted(a for kind, a in node.helpful if kind in (START, INST))
        by_fact, facts = self._by_fact, node.state.facts
        out = list(by_fact.get(-1, ()))
        while facts:
            low = facts & -facts
            out.extend(by_fact.get(low.bit_length() - 1, ()))
            facts ^= low
        out.sort()
        return out

    def _extend(
        self, state: State, timeline: Timeline, step: Step, running: tuple[tuple[int, int], ...]
    ) -> Iterator[tuple[State, Timeline, tuple[tuple[int, int], ...]]]:
        extended = timeline.extend(step, self._future(state, running))
        self.generated += 1
        if extended is None:
            self.inconsistent += 1
            return
        yield state, extended, running

    def _future(self, state: State, running: tuple[tuple[int, int], ...]) -> Future:
        """Return the happenings still to come after a step: running ends, later TILs."""
        ends = []
        for index, start_step in running:
            end = self.task.actions[index].end
            assert end is not None
            ends.append((start_step, end))
        deadlines = tuple(
            (self.task.tils[j].time, self._til_snaps[j])
            for j in range(state.til, len(self.task.tils))
        )
        return Future(tuple(ends), deadlines)

    @staticmethod
    def dead(node: Node) -> bool:
        """Tell whether the heuristic proved the node a dead end."""
        return node.h >= INFINITE
