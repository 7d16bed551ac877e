"""Temporal relaxed planning graph heuristic with helpful actions (FF over snap actions).

Each durative action becomes two relaxed operators: its start (adding the start
effects and a `pending` token) and its end (needing the token, the end condition and
the invariant). A running action starts with its token, and its `ended` token is a
goal, so the relaxed plan must finish what the state has started. Deletes are ignored;
numeric conditions are relaxed to intervals that effects can only widen. The graph is
built with precondition counters, so one evaluation costs time linear in the
relaxed-reachable part of the task, not in the number of layers times actions. The
relaxed operators and numeric intervals are `relaxation`'s.
"""

from __future__ import annotations

import copy
import math
import threading
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

from cbdi_planner.core import compiled
from cbdi_planner.relaxation import RelaxedOp, may_hold, relaxed_ops, widen
from cbdi_planner.state import State
from cbdi_planner.stn import END, START, TIL
from cbdi_planner.task import Task
from cbdi_planner.task import bit_positions as _bits

__all__ = ["INFINITE", "Estimate", "RelaxedPlanGraph"]

INFINITE = 1 << 30
KNOWN = 4096  # estimates remembered (oldest forgotten first): a few MB on a 30x30 map
BUILT = 3  # graphs kept for `RelaxedPlanGraph.of` (LRU; campus-30x30: some 10 MB each)


@dataclass(frozen=True, slots=True)
class Estimate:
    """A heuristic value and the helpful happenings `(kind, action)` of a state.

    `duration` sums the durations of the relaxed plan's actions: a rough estimate of
    the time still needed, which the anytime search weighs against makespan.
    """

    value: int
    helpful: frozenset[tuple[int, int]]
    duration: float = 0.0


@dataclass(slots=True)
class _Layers:
    """What `RelaxedPlanGraph._explore` has built so far.

    Each fact's first layer and the op that first added it (-1: not yet), each op's
    layer (-1: not fired), and the numeric intervals `[lo, hi]` the fired ops widened.
    """

    level: list[int]
    achiever: list[int]
    op_level: list[int]
    lo: list[float]
    hi: list[float]


class RelaxedPlanGraph:
    """Precomputed relaxed operators of a task; `estimate` evaluates one state."""

    def __init__(self, task: Task, compress: bool = False, core: str | None = None) -> None:
        """Build the relaxed operators; `compress`: one per action, for compressed search.

        A compressed search has no running actions, so a durative action can be one
        relaxed operator (FF's on the compressed task): it needs what its start needs
        and what its invariant and end need beyond the start's effects, and adds what
        both add. The relaxed plan then counts it once, and the graph is half as deep.
        `core`: the search core that explores (`cbdi_planner.core`; default: the
        environment's).
        """
        self.task = task
        n_facts, n_actions = len(task.facts), len(task.actions)
        self.pending = n_facts
        self.ended = n_facts + n_actions
        self.size = n_facts + 2 * n_actions + len(task.tils)
        self.ops, then = relaxed_ops(task, compress, self.pending, self.ended)
        self._index(then)
        module = compiled(core)
        self._core = module.Graph(self) if module is not None else None

    @property
    def core(self) -> object:
        """Return the compiled core's graph (None: the Python core explores)."""
        return self._core

    _built: OrderedDict[tuple[object, ...], tuple[RelaxedPlanGraph, object]] = OrderedDict()
    _building = threading.Lock()

    @classmethod
    def of(cls, task: Task, compress: bool = False, core: str | None = None) -> RelaxedPlanGraph:
        """A graph of `task`, built once for every task that differs only in its facts.

        A planner makes a task per request and per epoch from one grounding (the same
        actions and timed literals; another initial state, another goal maybe), and
        building the graph costs as much as a few hundred evaluations on a big map: the
        operators depend on the actions and on the numeric values their durations read,
        not on the goal, so a task with the same ones gets a copy of the graph built
        before (its operators shared, read only; its own goal and remembered estimates).
        """
        key = (
            id(task.actions),
            id(task.tils),
            task.init_nums,
            len(task.facts),
            compress,
            compiled(core) is not None,
        )
        with cls._building:
            found = cls._built.get(key)
            if found is not None:
                cls._built.move_to_end(key)
        if found is None:
            graph = cls(task, compress=compress, core=core)
            with cls._building:
                # the entry holds what the key's ids name, so they stay theirs
                cls._built[key] = (graph, (task.actions, task.tils))
                while len(cls._built) > BUILT:
                    cls._built.popitem(last=False)
            found = (graph, None)
        twin = copy.copy(found[0])
        twin.task = task
        twin.goal = _bits(task.goal)
        twin._known = {}
        return twin

    def _index(self, then: dict[int, int]) -> None:
        """Flatten the operators into parallel lists for the inner loops of `estimate`."""
        ops = self.ops
        users: list[list[int]] = [[] for _ in range(self.size)]
        adders: list[list[int]] = [[] for _ in range(self.size)]
        chained = set(then.values())
        for k, op in enumerate(ops):
            for f in op.pre if k not in chained else ():
                users[f].append(k)
            for f in op.add:
                adders[f].append(k)
        self.users = [tuple(u) for u in users]
        self.adders = [tuple(a) for a in adders]
        self.counts = [len(op.pre) for op in ops]
        self.op_pre = [op.pre for op in ops]
        self.op_add = [op.add for op in ops]
        self.op_kind = [op.kind for op in ops]
        self.op_action = [op.action for op in ops]
        # The facts an op adds split by whether some op counts them: the others (the
        # `pending` and `ended` tokens of chained actions, mostly) get a layer but need
        # no pass through the frontier.
        self.op_num_pre = [op.num_pre for op in ops]
        self.op_num_eff = [op.num_eff for op in ops]
        self.free = [k for k, op in enumerate(ops) if not op.pre and op.kind != TIL]
        self.til_ops = [k for k, op in enumerate(ops) if op.kind == TIL]
        self.goal = _bits(self.task.goal)
        self._known: dict[tuple[tuple[int, ...], object], Estimate] = {}
        self.op_duration = [self._duration(op) for op in ops]
        self.then = [then.get(k, -1) for k in range(len(ops))]
        # What firing op k does, in one record: (numeric or not, then, live, quiet). The
        # facts it adds are split by whether some op counts them: the others (mostly
        # the `pending` and `ended` tokens of chained actions) get a layer but need no
        # pass through the frontier. `_everything`: all adds live, for `extra` counters.
        self._fire = [
            (
                bool(op.num_pre or op.num_eff),
                self.then[k],
                tuple(f for f in op.add if users[f]),
                tuple(f for f in op.add if not users[f]),
            )
            for k, op in enumerate(ops)
        ]
        self._everything = [
            (numeric, nxt, op.add, ())
            for (numeric, nxt, _, _), op in zip(self._fire, ops, strict=True)
        ]
        self.chained_end = {ops[k].action: k for k in chained}
        self.start_op = {op.action: k for k, op in enumerate(ops) if op.kind == START}

    def _duration(self, op: RelaxedOp) -> float:
        """Return the (least) duration an op stands for: its action's, for a start."""
        if op.kind != START:
            return 0.0
        action = self.task.actions[op.action]
        low, _ = action.duration_bounds(self.task.init_nums, 0.0)
        return low if math.isfinite(low) else 0.0

    def aim(self, goal: int) -> None:
        """Estimate the distance to the facts `goal` from now on (the task's by default)."""
        self.goal = _bits(goal)

    def levels(self, state: State, facts: int) -> dict[int, int] | None:
        """Return the first layer of each of `facts` in the graph of `state` (None: one never)."""
        wanted = list(_bits(facts))
        reached = self._explore(state, wanted)
        if reached is None:
            return None
        return {f: reached[0][f] for f in wanted}

    def estimate(self, state: State) -> Estimate:
        """Return the relaxed plan length and the helpful happenings of `state`.

        The estimate is a function of the state and the goal aimed at, so the latest
        ones are remembered: a climbing step forgets what the step before saw, and a
        continual search evaluates again states a round before had reached.
        """
        key = (self.goal, state.key())
        known = self._known.get(key)
        if known is not None:
            return known
        goals = list(self.goal) + [self.ended + a for a in state.open]
        if self._core is not None:
            estimate = self._estimate_compiled(state, goals)
        else:
            estimate = self._estimate(state, goals)
        if len(self._known) >= KNOWN:
            del self._known[next(iter(self._known))]  # the oldest
        self._known[key] = estimate
        return estimate

    def _estimate(self, state: State, goals: list[int]) -> Estimate:
        """Explore the graph of `state` and extract the relaxed plan of `goals`."""
        reached = self._explore(state, goals)
        if reached is None:
            estimate = Estimate(INFINITE, frozenset())
        else:
            level, achiever, op_level = reached
            estimate = self._extract(goals, level, achiever, op_level, state)
        return estimate

    def _estimate_compiled(self, state: State, goals: list[int]) -> Estimate:
        """`_estimate` by the compiled core, in one call without the interpreter lock."""
        facts = state.facts
        packed = facts.to_bytes((facts.bit_length() + 7) // 8, "little")
        found = self._core.estimate(packed, state.open, state.til, state.nums, goals)  # type: ignore[union-attr]
        if found is None:
            return Estimate(INFINITE, frozenset())
        value, helpful, duration = found
        return Estimate(value, frozenset(helpful), duration)

    def _explore(
        self, state: State, goals: list[int]
    ) -> tuple[list[int], list[int], list[int]] | None:
        """Build the graph layer by layer until every goal is reached (None: never).

        Return each fact's first layer and first achiever, and each op's layer.
        Precondition counters make each layer cost only the operators its new facts
        touch; an operator whose numeric condition cannot hold yet waits. Ops fire in
        the order they became ready, so the first achiever of a fact is always the same.
        The compiled core, when it runs, does exactly this (without the interpreter lock).
        """
        if self._core is not None:
            facts = state.facts
            packed = facts.to_bytes((facts.bit_length() + 7) // 8, "little")
            found = self._core.explore(packed, state.open, state.til, state.nums, goals)
            return cast(tuple[list[int], list[int], list[int]] | None, found)
        layers = _Layers(
            [-1] * self.size,
            [-1] * self.size,
            [-1] * len(self.ops),
            list(state.nums),
            list(state.nums),
        )
        level = layers.level
        counts = self.counts[:]
        frontier = list(_bits(state.facts))
        frontier += [self.pending + a for a in state.open]
        for f in frontier:
            level[f] = 0
        missing = [g for g in set(goals) if level[g] < 0]
        ready = self.free + self.til_ops[state.til :]
        extra = self._running_ends(state, level, counts, ready)
        # A running action's end may count facts no op counts otherwise: then every
        # new fact goes through the frontier.
        fire = self._everything if extra else self._fire
        waiting: list[int] = []
        depth = 0
        while missing:
            self._count_down(frontier, counts, extra, ready)
            fired = self._fire_layer(layers, waiting + ready if waiting else ready, depth, fire)
            if fired is None:
                return None
            frontier, ready, waiting = fired
            depth += 1
            missing = [g for g in missing if level[g] < 0]
        return level, layers.achiever, layers.op_level

    def _count_down(
        self,
        frontier: list[int],
        counts: list[int],
        extra: dict[int, list[int]],
        ready: list[int],
    ) -> None:
        """Count the facts of `frontier` off the ops needing them; one needing none is ready.

        `extra`: the chained end ops of running actions and the facts they still need
        (`_running_ends`), which `users` does not list.
        """
        users = self.users
        for f in frontier:
            for k in users[f]:
                left = counts[k] - 1
                counts[k] = left
                if not left:
                    ready.append(k)
            if extra:
                for k in extra.get(f, ()):
                    counts[k] -= 1
                    if counts[k] == 0:
                        ready.append(k)

    def _fire_layer(
        self,
        layers: _Layers,
        due: list[int],
        depth: int,
        fire: Sequence[tuple[bool, int, tuple[int, ...], tuple[int, ...]]],
    ) -> tuple[list[int], list[int], list[int]] | None:
        """Fire at layer `depth` the ops of `due` not fired yet (None: not one could).

        Return the facts first reached (the next frontier), the ops made ready (the
        chained ends of the starts fired) and the ops held back because their numeric
        condition cannot hold yet. Numeric effects widen the intervals only after the
        whole layer, so no op of a layer sees the effect of another.
        """
        level, achiever, op_level = layers.level, layers.achiever, layers.op_level
        op_num_pre, op_num_eff = self.op_num_pre, self.op_num_eff
        frontier: list[int] = []
        ready: list[int] = []
        held: list[int] = []
        acting: list[int] = []  # ops with numeric effects, applied after the layer
        fired, next_level = False, depth + 1
        for k in due:
            if op_level[k] >= 0:
                continue
            numeric, nxt, live, quiet = fire[k]
            if numeric:
                if op_num_pre[k] and not all(
                    may_hold(c, layers.lo, layers.hi) for c in op_num_pre[k]
                ):
                    held.append(k)
                    continue
                if op_num_eff[k]:
                    acting.append(k)
            op_level[k] = depth
            fired = True
            if nxt >= 0:
                ready.append(nxt)
            for f in live:
                if level[f] < 0:
                    level[f] = next_level
                    achiever[f] = k
                    frontier.append(f)
            for f in quiet:
                if level[f] < 0:
                    level[f] = next_level
                    achiever[f] = k
        if not fired:
            return None
        for k in acting:
            for effect in op_num_eff[k]:
                widen(effect, layers.lo, layers.hi)
        return frontier, ready, held

    def _running_ends(
        self, state: State, level: list[int], counts: list[int], ready: list[int]
    ) -> dict[int, list[int]]:
        """Set up the counters of the chained end ops of running actions.

        A chained end op is not in `users`; for an action the state has started, its
        conditions may not hold any more, so they are counted here (`pending` holds).
        """
        extra: dict[int, list[int]] = {}
        for a in state.open:
            k = self.chained_end.get(a)
            if k is None:
                continue
            need = [f for f in self.op_pre[k] if level[f] < 0]
            counts[k] = len(need)
            if not need:
                ready.append(k)
            for f in need:
                extra.setdefault(f, []).append(k)
        return extra

    def _extract(
        self,
        goals: list[int],
        level: list[int],
        achiever: list[int],
        op_level: list[int],
        state: State,
    ) -> Estimate:
        """Extract a relaxed plan backwards (FF); helpful = applicable ops adding layer-1 goals."""
        top = max((level[g] for g in goals), default=0)
        buckets: list[set[int]] = [set() for _ in range(top + 1)]
        for g in goals:
            buckets[level[g]].add(g)
        chosen: set[int] = set()
        done: set[int] = set()
        sought: list[int] = []  # facts chosen ends of actions started at layer 0 give
        op_pre, op_add, ops = self.op_pre, self.op_add, self.ops
        for depth in range(top, 0, -1):
            for g in buckets[depth]:
                if g in done:
                    continue
                k = achiever[g]
                if depth == 2 and ops[k].kind == END:
                    sought.append(g)
                if k in chosen:
                    continue
                chosen.add(k)
                done.update(op_add[k])
                for p in op_pre[k]:
                    if level[p] > 0 and p not in done:
                        buckets[level[p]].add(p)
        helpful = set()
        if top >= 1:
            for g in buckets[1]:
                for k in self.adders[g]:
                    if op_level[k] == 0:
                        op = ops[k]
                        if op.kind != TIL or op.action == state.til:
                            helpful.add((op.kind, op.action))
        # FF's helpful actions are all those adding a goal of layer 1; a durative
        # action adds its facts a layer after its start, so every action that could
        # start now and whose end gives a fact the relaxed plan ends an action for is
        # helpful too, not only the one the relaxed plan happened to choose.
        for g in sought:
            for k in self.adders[g]:
                op = ops[k]
                if op.kind == END and op_level[self.start_op[op.action]] == 0:
                    helpful.add((START, op.action))
        duration = 0.0  # summed in set order, one addition at a time, as the compiled core does
        for k in chosen:
            duration += self.op_duration[k]
        return Estimate(len(chosen), frozenset(helpful), duration)
