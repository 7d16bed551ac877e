"""The optimised heuristic returns exactly what the straightforward one does.

Searches on the recycling maps, IPC problems and small feature tasks record every state
the heuristic evaluates (with the goal it aimed at then, which a goal agenda changes);
each, and a copy with a few facts flipped, is evaluated again by `heuristic_reference`
(the heuristic before issue 13), and both estimates (value, helpful happenings,
duration) and graph layers must be equal. Snap and compressed searches both run, so
states with running actions are covered.
"""

from __future__ import annotations

import os
import random
from dataclasses import replace
from pathlib import Path

import heuristic_reference as reference
import pytest
from test_features import (
    CONDITIONAL,
    CONDITIONAL_PROBLEM,
    MATCHES,
    MATCHES_PROBLEM,
    NUMERIC,
    NUMERIC_PROBLEM,
    TIL,
    TIL_PROBLEM,
)

from cbdi_planner.grounding import ground
from cbdi_planner.heuristic import RelaxedPlanGraph
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.search import Budget, search
from cbdi_planner.state import State, initial_state
from cbdi_planner.task import Task

ROOT = Path(__file__).resolve().parents[2]
RECYCLING = ROOT / "domains/recycling"
BENCHMARKS = Path(os.environ.get("CBDI_TEMPORAL_BENCHMARKS", "/work/shared/benchmarks/temporal"))
SAMPLES = 120  # states compared per search at most (spread over the whole search)


def _recycling(name: str) -> Task:
    domain_file = RECYCLING / "pddl/domain.pddl"
    problem_file = RECYCLING / "problems" / f"{name}.pddl"
    domain = parse_domain(domain_file.read_text(), str(domain_file))
    return ground(domain, parse_problem(problem_file.read_text(), domain, str(problem_file)))


def _ipc(domain_name: str, problem_name: str) -> Task:
    folder = BENCHMARKS / domain_name
    if not (folder / f"{problem_name}.pddl").exists():
        pytest.skip(f"benchmark {folder / problem_name} is not available")
    domain = parse_domain((folder / "domain.pddl").read_text())
    return ground(domain, parse_problem((folder / f"{problem_name}.pddl").read_text(), domain))


def _text(domain_text: str, problem_text: str) -> Task:
    domain = parse_domain(domain_text, "domain.pddl")
    return ground(domain, parse_problem(problem_text, domain, "problem.pddl"))


def _sampled(
    monkeypatch: pytest.MonkeyPatch, task: Task, compress: bool, strategy: str, expansions: int
) -> list[tuple[int, State]]:
    """Return `(goal facts, state)` of the evaluations of a bounded search, spread evenly."""
    seen: list[tuple[tuple[int, ...], State]] = []
    estimate = RelaxedPlanGraph.estimate

    def recording(self: RelaxedPlanGraph, state: State) -> object:
        seen.append((self.goal, state))
        return estimate(self, state)

    monkeypatch.setattr(RelaxedPlanGraph, "estimate", recording)
    # the Python core's search: the compiled one evaluates its states without Python
    monkeypatch.setenv("CBDI_SEARCH_CORE", "python")
    search(task, strategy=strategy, budget=Budget(max_expansions=expansions), compress=compress)
    monkeypatch.undo()
    step = max(1, len(seen) // SAMPLES)
    return [(sum(1 << f for f in goal), state) for goal, state in seen[::step]]


def _shaken(state: State, task: Task, rng: random.Random) -> State:
    """Return `state` with a few facts flipped: states no search reaches, such as a
    running action whose end condition no longer holds (its end then waits on facts)."""
    facts = state.facts
    for _ in range(rng.randint(1, 4)):
        facts ^= 1 << rng.randrange(len(task.facts))
    for index in state.open:
        end = task.actions[index].end
        assert end is not None
        needs = [f for f in range(len(task.facts)) if (end.pre | task.actions[index].inv) >> f & 1]
        if needs and rng.random() < 0.7:
            facts &= ~(1 << rng.choice(needs))
    return replace(state, facts=facts)


def _assert_same(
    monkeypatch: pytest.MonkeyPatch,
    task: Task,
    strategies: tuple[str, ...] = ("ff", "bfs"),
    expansions: int = 60,
    least: int = 100,
) -> None:
    compared, rng = 0, random.Random(13)
    for compress, strategy in ((c, s) for c in (False, True) for s in strategies):
        new = RelaxedPlanGraph(task, compress=compress)
        old = reference.RelaxedPlanGraph(task, compress=compress)
        for goal, sampled in _sampled(monkeypatch, task, compress, strategy, expansions):
            new.aim(goal)
            old.aim(goal)
            for state in (sampled, _shaken(sampled, task, rng)):
                got, want = new.estimate(state), old.estimate(state)
                assert (got.value, got.helpful, got.duration) == (
                    want.value,
                    want.helpful,
                    want.duration,
                ), state
                assert new.levels(state, goal) == old.levels(state, goal), state
                compared += 1
    print(f"{compared} states compared")
    assert compared >= least


@pytest.mark.parametrize("name", ["paper-7x7", "warehouse-15x15", "campus-30x30"])
def test_recycling_estimates_match_the_reference(
    monkeypatch: pytest.MonkeyPatch, name: str
) -> None:
    _assert_same(monkeypatch, _recycling(name), ("auto", "bfs"), expansions=40)


@pytest.mark.parametrize(
    ("domain_name", "problem_name"),
    [("zenotravel", "p08"), ("matchcellar", "p03"), ("driverlog", "p08"), ("crewplanning", "p03")],
)
def test_ipc_estimates_match_the_reference(
    monkeypatch: pytest.MonkeyPatch, domain_name: str, problem_name: str
) -> None:
    _assert_same(monkeypatch, _ipc(domain_name, problem_name), least=50)


@pytest.mark.parametrize(
    ("domain_text", "problem_text"),
    [
        (TIL, TIL_PROBLEM),
        (NUMERIC, NUMERIC_PROBLEM),
        (CONDITIONAL, CONDITIONAL_PROBLEM),
        (MATCHES, MATCHES_PROBLEM),
    ],
    ids=["til", "numeric", "conditional", "matches"],
)
def test_feature_estimates_match_the_reference(
    monkeypatch: pytest.MonkeyPatch, domain_text: str, problem_text: str
) -> None:
    _assert_same(monkeypatch, _text(domain_text, problem_text), least=10)


def test_a_graph_is_built_once_for_tasks_that_differ_only_in_their_facts_or_goal() -> None:
    """`RelaxedPlanGraph.of`: a planner's per-epoch task reuses the operators built for
    an earlier one of the same grounding, whatever its initial state and goal, and
    estimates exactly as a graph built anew."""
    task = _recycling("warehouse-15x15")
    rng = random.Random(7)
    first = RelaxedPlanGraph.of(task)
    moved = replace(task, init_facts=_shaken(initial_state(task), task, rng).facts)
    again = RelaxedPlanGraph.of(moved)
    assert again.ops is first.ops and again.task is moved and again._known is not first._known
    state = initial_state(moved)
    assert again.estimate(state) == RelaxedPlanGraph(moved).estimate(state)
    again.aim(0)  # one copy's goal is its own
    assert first.goal == RelaxedPlanGraph(task).goal
    other = replace(task, goal=task.goal & (task.goal - 1))  # another goal: the same ops
    aimed = RelaxedPlanGraph.of(other)
    assert aimed.ops is first.ops and aimed.goal == RelaxedPlanGraph(other).goal
    assert aimed.estimate(initial_state(other)) == RelaxedPlanGraph(other).estimate(
        initial_state(other)
    )
    slower = replace(task, init_nums=tuple(v + 1 for v in task.init_nums))  # other values
    assert not task.init_nums or RelaxedPlanGraph.of(slower).ops is not first.ops
