"""Search nodes and their successors: one happening appended to a partial plan.

A node couples a state with the timeline (STN) of the plan that reached it. A
successor exists only if the happening is applicable in the state, breaks no running
invariant and leaves the timeline consistent.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from cbdi_planner.core import compiled
from cbdi_planner.heuristic import INFINITE, RelaxedPlanGraph
from cbdi_planner.moves import CompiledMoves, goal_of, til_snaps
from cbdi_planner.state import State, apply_end, apply_start, apply_til, is_goal
from cbdi_planner.stn import END, INST, START, TIL, Future, Oracle, Step, Timeline
from cbdi_planner.task import Task, bit_positions

__all__ = ["Expander", "Move", "Node", "Successor", "needs"]

Running = tuple[tuple[int, int], ...]
# A step to append, with the state after it and the actions running then.
Placed = tuple[Step, State, Running]


@dataclass(frozen=True, slots=True)
class Node:
    """A search node; `running` pairs each running action with its start step."""

    state: State
    timeline: Timeline
    running: tuple[tuple[int, int], ...]
    h: int
    helpful: frozenset[tuple[int, int]]
    h_time: float = 0.0
    # The compiled core's node (`cbdi_planner_core.SearchNode`; None: the Python core's),
    # which its search loops start from.
    handle: Any = field(default=None, compare=False)

    @property
    def makespan(self) -> float:
        """Return the makespan of the partial plan so far."""
        return self.timeline.makespan


@dataclass(frozen=True, slots=True)
class Move:
    """A happening applied to a node's state: the new state, and the steps to schedule.

    Two steps for a compressed action (its start and end), one otherwise. `placing`:
    the compiled core's steps to schedule (None: the Python core's move).
    """

    state: State
    running: Running
    steps: tuple[Placed, ...]
    placing: Any = field(default=None, compare=False)

    @property
    def first(self) -> Step:
        """Return the step that chose the move (a start, an end, an action or a literal)."""
        return self.steps[0][0]


Successor = tuple[State, Timeline, Running]


def needs(task: Task) -> list[int]:
    """What each action needs before it starts: its start condition, and the part of
    its invariant the start does not add (the invariant holds right after it)."""
    return [a.start.pre | (a.inv & ~a.start.add) for a in task.actions]


def prepare(task: Task, core: str | None = None) -> None:
    """Build ahead what an `Expander` of `task` needs and keeps (call from a worker
    thread): on the compiled core the task's moves, built once per task; so an expander
    made on a service's event loop finds them built (campus-30x30: about 100 ms)."""
    module = compiled(core)
    if module is not None:
        CompiledMoves.of(task, module, needs)


class Expander:
    """Generate and evaluate successors; counts what it does in `generated`/`evaluated`."""

    def __init__(
        self,
        task: Task,
        epsilon: float,
        compress: bool = False,
        core: str | None = None,
    ) -> None:
        """`core`: the search core (`cbdi_planner.core`; default: the environment's)."""
        self.task = task
        self.epsilon = epsilon
        self.compress = compress
        self.rpg = RelaxedPlanGraph.of(task, compress=compress, core=core)
        module = compiled(core)
        self.subgoal: int | None = None
        self.generated = 0
        self.evaluated = 0
        self.inconsistent = 0
        # Compiled: the moves made and scheduled there, the task handed over once.
        self._compiled = CompiledMoves.of(task, module, needs) if module is not None else None
        self._oracle: Oracle | None = None
        self._needs: list[int] = []
        self._by_fact: dict[int, list[int]] = {}
        # Compiled: its nodes and search loops (`loops`), this expander's aim and counts.
        self.native: Any = None
        # The steps of the nodes made from handles, by what they are: a continual
        # search's rounds return plans that share their first steps.
        self._steps: dict[tuple[int, int, int, float, float], Step] = {}
        if self._compiled is not None:
            self._oracle = self._compiled.oracle
            self._til_snaps = list(self._compiled.tils)
            self.native = module.Search(  # type: ignore[union-attr]
                self._compiled.core, self.rpg.core, goal_of(task), compress, epsilon
            )
            return
        self._til_snaps = til_snaps(task)
        self._needs = needs(task)
        # Each action under the lowest fact it needs (-1: none), so `successors` looks
        # only at actions whose condition can hold in a state.
        for action in task.actions:
            need = self._needs[action.index]
            low = (need & -need).bit_length() - 1
            self._by_fact.setdefault(low, []).append(action.index)

    @property
    def oracle(self) -> Oracle | None:
        """Return the compiled core's snap codes (None: the Python core's timelines)."""
        return self._oracle

    def root(self, state: State) -> Node:
        """Return the node of `state` with an empty plan (no running actions allowed)."""
        if state.open:
            raise ValueError("a search root cannot have running actions")
        if self.native is not None:
            facts = state.facts
            packed = facts.to_bytes((facts.bit_length() + 7) // 8, "little")
            return self.node_of(self.native.root(packed, state.nums, state.til))
        return self.evaluate(state, Timeline.start(self.epsilon, self._oracle), ())

    def reevaluate(self, node: Node) -> Node:
        """Return `node` evaluated again (under the current aim)."""
        if node.handle is not None and self.native is not None:
            return self.node_of(self.native.reevaluate(node.handle))
        return self.evaluate(node.state, node.timeline, node.running)

    def node_of(self, handle: Any) -> Node:
        """Return the node of a compiled core's handle (and count what it did)."""
        self.sync()
        compiled = self._compiled
        assert compiled is not None
        facts, nums, open_, til, running, h, helpful, h_time, net, placed = handle.view()
        made, snaps = self._steps, compiled.snaps
        steps = []
        for row in placed:  # (kind, action, partner, low, high)
            step = made.get(row)
            if step is None:
                kind, action, partner, low, high = row
                step = made[row] = Step(kind, action, snaps[kind][action], partner, low, high)
            steps.append(step)
        timeline = Timeline(tuple(steps), net, self.epsilon, net.span, compiled.oracle)
        state = State(int.from_bytes(facts, "little"), nums, open_, til)
        return Node(state, timeline, running, h, frozenset(helpful), h_time, handle)

    def sync(self) -> None:
        """Count what the compiled core did since the last call."""
        if self.native is not None:
            generated, evaluated, inconsistent = self.native.take_counts()
            self.generated += generated
            self.evaluated += evaluated
            self.inconsistent += inconsistent

    def aim(self, subgoal: int | None) -> None:
        """Search for the facts `subgoal` only (a stage of a goal agenda); None: the goal."""
        self.subgoal = subgoal
        self.rpg.aim(self.task.goal if subgoal is None else subgoal)
        if self.native is not None:
            self.native.aim(None if subgoal is None else list(bit_positions(subgoal)))

    def reached(self, state: State) -> bool:
        """Tell whether `state` is a goal of the current aim (no action may still run)."""
        if self.subgoal is None:
            return is_goal(self.task, state)
        return not state.open and self.subgoal & ~state.facts == 0

    def evaluate(
        self, state: State, timeline: Timeline, running: tuple[tuple[int, int], ...]
    ) -> Node:
        """Build a node, computing its heuristic value."""
        estimate = self.rpg.estimate(state)
        self.evaluated += 1
        return Node(state, timeline, running, estimate.value, estimate.helpful, estimate.duration)

    def successors(self, node: Node, helpful_only: bool = False) -> Iterator[Successor]:
        """Yield the consistent successors (ends and the next timed literal first)."""
        for move in self.moves(node, helpful_only):
            timeline = self.schedule(node.timeline, move)
            if timeline is not None:
                yield move.state, timeline, move.running

    def moves(self, node: Node, helpful_only: bool = False) -> Iterator[Move]:
        """Yield the applicable happenings of a node, not yet put on its timeline.

        A lazy search keeps these and schedules (`schedule`) only the ones it takes.
        """
        if self._compiled is not None:
            return self._moves_compiled(node, helpful_only, self._compiled)
        return self._moves_python(node, helpful_only)

    def _moves_python(self, node: Node, helpful_only: bool) -> Iterator[Move]:
        """`moves` by the Python core, one happening at a time."""
        state, task, steps = node.state, self.task, len(node.timeline.steps)
        for index, start_step in node.running:
            action = task.actions[index]
            assert action.end is not None
            new = apply_end(task, state, action)
            if new is None:
                continue
            begun = node.timeline.steps[start_step]
            step = Step(END, index, action.end, start_step, begun.low, begun.high)
            running = tuple(r for r in node.running if r[0] != index)
            yield self._move(new, running, ((step, new, running),))
        if state.til < len(task.tils):
            new = apply_til(task, state)
            if new is not None:
                when = task.tils[state.til].time
                step = Step(TIL, state.til, self._til_snaps[state.til], -1, when, when)
                yield self._move(new, node.running, ((step, new, node.running),))
        facts, needs = state.facts, self._needs
        for index in self._candidates(node, helpful_only):
            action = task.actions[index]
            if needs[index] & ~facts:
                continue
            new = apply_start(task, state, action)
            if new is None:
                continue
            if action.end is None:
                step = Step(INST, action.index, action.start)
                yield self._move(new, node.running, ((step, new, node.running),))
                continue
            low, high = action.duration_bounds(state.nums, self.epsilon)
            if low > high or high <= 0:
                continue
            step = Step(START, action.index, action.start, -1, low, high)
            running = tuple(sorted((*node.running, (action.index, steps))))
            if not self.compress:
                yield self._move(new, running, ((step, new, running),))
                continue
            # The whole action at once: the state passes through the start's effects
            # (the end condition and the invariant are checked there, as a sequential
            # execution would); the timeline still lifts the two steps into a partial
            # order, so later actions may overlap this one.
            ended = apply_end(task, new, action)
            if ended is None:
                continue
            end = Step(END, action.index, action.end, steps, low, high)
            placed = ((step, new, running), (end, ended, node.running))
            yield self._move(ended, node.running, placed)

    def _moves_compiled(
        self, node: Node, helpful_only: bool, compiled: CompiledMoves
    ) -> Iterator[Move]:
        """`moves` by the compiled core: every move made in one call."""
        state, steps = node.state, node.timeline.steps
        facts = state.facts
        found = compiled.core.moves(
            facts.to_bytes((facts.bit_length() + 7) // 8, "little"),
            state.nums,
            state.open,
            state.til,
            [(i, s, steps[s].low, steps[s].high) for i, s in node.running],
            len(steps),
            self._candidates(node, True) if helpful_only else None,
            self.compress,
            self.epsilon,
        )
        snaps, base, from_bytes = compiled.snaps, state.nums, int.from_bytes
        for placing, *made in found:
            placed = []
            for kind, index, partner, low, high, packed, nums, open_, til, running in made:
                new = State(
                    from_bytes(packed, "little"), base if nums is None else nums, open_, til
                )
                placed.append(
                    (Step(kind, index, snaps[kind][index], partner, low, high), new, running)
                )
            self.generated += 1
            yield Move(new, running, tuple(placed), placing)

    def _move(
        self, state: State, running: Running, steps: tuple[Placed, ...], placing: Any = None
    ) -> Move:
        self.generated += 1
        return Move(state, running, steps, placing)

    def schedule(self, timeline: Timeline, move: Move) -> Timeline | None:
        """Return `timeline` with the steps of `move` appended (None: inconsistent)."""
        compiled = self._compiled
        if move.placing is not None and compiled is not None and timeline.oracle is compiled.oracle:
            net = compiled.core.schedule(timeline.net, move.placing, self.epsilon)
            if net is None:
                self.inconsistent += 1
                return None
            placed = move.steps  # one step, or a compressed action's two
            added = (placed[0][0],) if len(placed) == 1 else (placed[0][0], placed[1][0])
            return Timeline(timeline.steps + added, net, self.epsilon, net.span, timeline.oracle)
        for step, state, running in move.steps:
            extended = timeline.extend(step, self._future(state, running))
            if extended is None:
                self.inconsistent += 1
                return None
            timeline = extended
        return timeline

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
