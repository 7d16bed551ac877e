"""The goal agenda of `auto`: goal facts one at a time, and the fall-back when it fails.

Plans go through `kairos validate` (`plan_and_validate`, `validate`).
"""

from __future__ import annotations

from pathlib import Path

from planning import EPSILON, plan_and_validate, validate

from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.search import Budget, search

ROOT = Path(__file__).resolve().parents[2]
RECYCLING = ROOT / "domains/recycling"

# The nearest goal, (g1), is one step away by `a`, but `a` spends the only token: from
# there (g2) cannot be reached. Only `b` then `c` reach both.
TRAP = """
(define (domain trap)
  (:requirements :durative-actions)
  (:predicates (t) (m) (g1) (g2))
  (:durative-action a
    :parameters ()
    :duration (= ?duration 1)
    :condition (at start (t))
    :effect (and (at start (not (t))) (at end (g1))))
  (:durative-action b
    :parameters ()
    :duration (= ?duration 1)
    :condition (at start (t))
    :effect (and (at start (not (t))) (at end (m))))
  (:durative-action c
    :parameters ()
    :duration (= ?duration 1)
    :condition (at start (m))
    :effect (and (at end (g1)) (at end (g2)))))
"""

TRAP_PROBLEM = """
(define (problem trap1)
  (:domain trap)
  (:init (t))
  (:goal (and (g1) (g2))))
"""


def test_agenda_stuck_on_a_dead_end_falls_back_to_the_whole_goal(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, TRAP, TRAP_PROBLEM)
    assert planned.result.stats.strategy != "goals"
    assert [a.name for a in planned.plan.actions] == ["b", "c"]


def test_agenda_plans_the_30x30_map_that_climbing_to_the_whole_goal_cannot(
    tmp_path: Path,
) -> None:
    """24 items on a 30x30 campus: `ff` alone times out after 60 s, the agenda takes ~2 s."""
    domain_file = RECYCLING / "pddl/domain.pddl"
    problem_file = RECYCLING / "problems/campus-30x30.pddl"
    domain = parse_domain(domain_file.read_text(), str(domain_file))
    task = ground(domain, parse_problem(problem_file.read_text(), domain, str(problem_file)))
    result = search(task, budget=Budget(max_seconds=60), epsilon=EPSILON)
    assert result.status == "solved" and result.plan is not None
    assert result.stats.strategy == "goals"
    plan_file = tmp_path / "plan.txt"
    plan_file.write_text(result.plan.to_ipc())
    valid, output = validate(domain_file, problem_file, plan_file)
    assert valid, output
    recycles = [a for a in result.plan.actions if a.name.startswith("recycle")]
    assert len(recycles) == 24
