"""Compressed search: whole actions when no concurrency is required, snap actions else.

Each plan goes through `kairos validate`. The cases: a task that needs overlapping
actions is recognised (and its compressed space really has no plan), a task that does
not is searched compressed and still gets overlapping actions from the schedule, and
a need the static test misses is caught by the fall-back to snap actions.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from planning import EPSILON, plan_and_validate, validate
from test_features import DURATIVE, DURATIVE_PROBLEM, MATCHES, MATCHES_PROBLEM

from cbdi_planner.compression import needs_concurrency
from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.search import Budget, search
from cbdi_planner.task import Task

BENCHMARKS = Path(os.environ.get("CBDI_TEMPORAL_BENCHMARKS", "/work/shared/benchmarks/temporal"))


def _task(domain_text: str, problem_text: str) -> Task:
    domain = parse_domain(domain_text, "domain.pddl")
    return ground(domain, parse_problem(problem_text, domain, "problem.pddl"))


# A lock (a hoist unavailable while it works) is not a need for concurrency; a match
# that is lit only while it burns, read by another action, is.
LOCK = """
(define (domain lock)
  (:requirements :typing :durative-actions)
  (:types hoist crate)
  (:predicates (free ?h - hoist) (moved ?c - crate))
  (:durative-action move
    :parameters (?h - hoist ?c - crate)
    :duration (= ?duration 3)
    :condition (and (at start (free ?h)))
    :effect (and (at start (not (free ?h))) (at end (free ?h)) (at end (moved ?c)))))
"""

LOCK_PROBLEM = """
(define (problem lock1)
  (:domain lock)
  (:objects h1 h2 - hoist c1 c2 c3 - crate)
  (:init (free h1) (free h2))
  (:goal (and (moved c1) (moved c2) (moved c3))))
"""

# `a` can end only after `b` has started, and `b` can start only after `a` has: no
# fact is temporary, so the static test sees no need, yet every plan overlaps them.
HIDDEN = """
(define (domain hidden)
  (:requirements :durative-actions)
  (:predicates (ready) (h) (g) (done-a) (done-b))
  (:durative-action a
    :parameters ()
    :duration (= ?duration 2)
    :condition (and (at start (ready)) (at end (g)))
    :effect (and (at start (h)) (at end (done-a))))
  (:durative-action b
    :parameters ()
    :duration (= ?duration 1)
    :condition (and (at start (h)))
    :effect (and (at start (g)) (at end (done-b)))))
"""

HIDDEN_PROBLEM = """
(define (problem hidden1)
  (:domain hidden)
  (:init (ready))
  (:goal (and (done-a) (done-b))))
"""


def test_temporary_facts_read_by_others_need_concurrency() -> None:
    assert needs_concurrency(_task(MATCHES, MATCHES_PROBLEM))
    assert not needs_concurrency(_task(LOCK, LOCK_PROBLEM))
    # `busy` is temporary but read only by the action that makes it so.
    assert not needs_concurrency(_task(DURATIVE, DURATIVE_PROBLEM))


def test_compressed_space_of_required_concurrency_has_no_plan() -> None:
    task = _task(MATCHES, MATCHES_PROBLEM)
    forced = search(task, compress=True, strategy="bfs", budget=Budget(max_seconds=10))
    assert forced.status == "unsolvable"
    auto = search(task, budget=Budget(max_seconds=10))
    assert auto.status == "solved" and not auto.stats.compressed


def test_compressed_plan_keeps_independent_actions_overlapping(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, LOCK, LOCK_PROBLEM)
    assert planned.result.stats.compressed
    moves = sorted((a.time, a.time + (a.duration or 0.0)) for a in planned.plan.actions)
    assert len(moves) == 3
    # Two hoists: two crates move at once, the third after one of them (makespan 6).
    assert moves[1][0] < moves[0][1]
    assert planned.plan.makespan == pytest.approx(6.0 + EPSILON, abs=2 * EPSILON)


def test_need_missed_by_the_static_test_falls_back_to_snap_actions(tmp_path: Path) -> None:
    task = _task(HIDDEN, HIDDEN_PROBLEM)
    assert not needs_concurrency(task)
    assert search(task, compress=True, strategy="bfs").status == "unsolvable"
    planned = plan_and_validate(tmp_path, HIDDEN, HIDDEN_PROBLEM)
    assert not planned.result.stats.compressed
    a, b = planned.plan.actions
    assert a.time < b.time < a.time + (a.duration or 0.0)


@pytest.mark.parametrize(("name", "problem"), [("depots", "p03"), ("elevator", "p01")])
def test_ipc_problems_out_of_reach_of_snap_search(tmp_path: Path, name: str, problem: str) -> None:
    """Both time out after 60 s on snap actions; compressed, they solve in seconds."""
    folder = BENCHMARKS / name
    if not folder.exists():
        pytest.skip(f"benchmark {folder} is not available")
    domain = parse_domain((folder / "domain.pddl").read_text())
    task = ground(domain, parse_problem((folder / f"{problem}.pddl").read_text(), domain))
    result = search(task, budget=Budget(max_seconds=60), epsilon=EPSILON)
    assert result.status == "solved" and result.plan is not None and result.stats.compressed
    plan_file = tmp_path / "plan.txt"
    plan_file.write_text(result.plan.to_ipc())
    valid, output = validate(folder / "domain.pddl", folder / f"{problem}.pddl", plan_file)
    assert valid, output
