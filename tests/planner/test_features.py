"""One small domain per PDDL 2.1 feature the planner supports.

Each test plans, has Kairos validate the plan (in `plan_and_validate`) and then checks
a property of the feature: that it was used, and used well (no inflated makespan,
actions inside their window, durations inside their bounds).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from planning import EPSILON, plan_and_validate, solve, status_of

from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem

TOL = 1e-6

# -- durative actions: at start / over all / at end ---------------------------------

DURATIVE = """
(define (domain durative)
  (:requirements :typing :durative-actions)
  (:types robot room)
  (:predicates (at ?r - robot ?x - room) (door ?x - room) (busy ?r - robot)
               (visited ?r - robot ?x - room))
  (:durative-action go
    :parameters (?r - robot ?from ?to - room)
    :duration (= ?duration 2)
    :condition (and (at start (at ?r ?from))
                    (at start (not (busy ?r)))
                    (over all (door ?to))
                    (at end (busy ?r)))
    :effect (and (at start (not (at ?r ?from)))
                 (at start (busy ?r))
                 (at end (not (busy ?r)))
                 (at end (at ?r ?to))
                 (at end (visited ?r ?to)))))
"""

DURATIVE_PROBLEM = """
(define (problem two-robots)
  (:domain durative)
  (:objects r1 r2 - robot a b c - room)
  (:init (at r1 a) (at r2 b) (door a) (door b) (door c))
  (:goal (and (visited r1 c) (visited r2 c))))
"""


def test_durative_actions_run_in_parallel(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, DURATIVE, DURATIVE_PROBLEM)
    assert len(planned.plan) == 2
    assert all(duration == pytest.approx(2.0) for _, duration in planned.named("go"))
    # two independent moves overlap: the makespan is one move, not two
    assert planned.plan.makespan < 2.0 + 10 * EPSILON


def test_over_all_condition_is_needed(tmp_path: Path) -> None:
    problem = DURATIVE_PROBLEM.replace("(door c)", "")
    assert status_of(DURATIVE, problem) == "unsolvable"


# -- typing: hierarchy and either -----------------------------------------------------

TYPING = """
(define (domain typing)
  (:requirements :typing :durative-actions)
  (:types vehicle place - object
          truck car - vehicle
          pickup - truck
          bike - object)
  (:predicates (at ?x - (either vehicle bike) ?p - place) (road ?a ?b - place))
  (:durative-action drive
    :parameters (?v - vehicle ?a ?b - place)
    :duration (= ?duration 3)
    :condition (and (at start (at ?v ?a)) (over all (road ?a ?b)))
    :effect (and (at start (not (at ?v ?a))) (at end (at ?v ?b))))
  (:durative-action ride
    :parameters (?x - (either bike car) ?a ?b - place)
    :duration (= ?duration 5)
    :condition (and (at start (at ?x ?a)))
    :effect (and (at start (not (at ?x ?a))) (at end (at ?x ?b)))))
"""

TYPING_PROBLEM = """
(define (problem typing1)
  (:domain typing)
  (:objects p1 - pickup t1 - truck k1 - bike x y - place)
  (:init (at p1 x) (at t1 x) (at k1 x) (road x y))
  (:goal (and (at p1 y) (at t1 y) (at k1 y))))
"""


def test_type_hierarchy_and_either(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, TYPING, TYPING_PROBLEM)
    names = {a.name for a in planned.plan.actions}
    assert "drive p1 x y" in names  # a pickup is a truck is a vehicle
    assert "drive t1 x y" in names
    assert "ride k1 x y" in names  # a bike matches (either bike car)
    domain = parse_domain(TYPING)
    task = ground(domain, parse_problem(TYPING_PROBLEM, domain))
    grounded = {a.name.split()[0] + " " + a.name.split()[1] for a in task.actions}
    assert "drive k1" not in grounded  # a bike is no vehicle
    assert "ride t1" not in grounded  # a truck is neither bike nor car


# -- constants ------------------------------------------------------------------------

CONSTANTS = """
(define (domain constants)
  (:requirements :typing :durative-actions)
  (:types robot place)
  (:constants home - place)
  (:predicates (at ?r - robot ?p - place) (charged ?r - robot))
  (:durative-action go-home
    :parameters (?r - robot ?from - place)
    :duration (= ?duration 2)
    :condition (and (at start (at ?r ?from)) (at start (not (= ?from home))))
    :effect (and (at start (not (at ?r ?from))) (at end (at ?r home))))
  (:durative-action charge
    :parameters (?r - robot)
    :duration (= ?duration 4)
    :condition (and (over all (at ?r home)))
    :effect (and (at end (charged ?r)))))
"""

CONSTANTS_PROBLEM = """
(define (problem constants1)
  (:domain constants)
  (:objects r1 - robot field - place)
  (:init (at r1 field))
  (:goal (and (charged r1) (at r1 home))))
"""


def test_constants(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, CONSTANTS, CONSTANTS_PROBLEM)
    assert [a.name for a in planned.plan.actions] == ["go-home r1 field", "charge r1"]
    assert planned.start_of("charge") >= 2.0


# -- negative preconditions -----------------------------------------------------------

NEGATIVE = """
(define (domain negative)
  (:requirements :typing :negative-preconditions)
  (:types door)
  (:predicates (locked ?d - door) (open ?d - door) (alarm))
  (:action unlock
    :parameters (?d - door)
    :precondition (and (locked ?d) (not (alarm)))
    :effect (not (locked ?d)))
  (:action open-door
    :parameters (?d - door)
    :precondition (and (not (locked ?d)) (not (open ?d)))
    :effect (open ?d))
  (:action disarm
    :parameters ()
    :precondition (alarm)
    :effect (not (alarm))))
"""

NEGATIVE_PROBLEM = """
(define (problem negative1)
  (:domain negative)
  (:objects d1 d2 - door)
  (:init (locked d1) (alarm))
  (:goal (and (open d1) (open d2) (not (locked d1)) (not (alarm)))))
"""


def test_negative_preconditions(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, NEGATIVE, NEGATIVE_PROBLEM)
    names = [a.name for a in planned.plan.actions]
    assert set(names) == {"disarm", "unlock d1", "open-door d1", "open-door d2"}
    assert names.index("disarm") < names.index("unlock d1") < names.index("open-door d1")
    assert all(a.duration is None for a in planned.plan.actions)


# -- equality -------------------------------------------------------------------------

EQUALITY = """
(define (domain equality)
  (:requirements :typing :equality :durative-actions)
  (:types item)
  (:predicates (linked ?a ?b - item) (marked ?a - item))
  (:durative-action link
    :parameters (?a ?b - item)
    :duration (= ?duration 1)
    :condition (and (at start (not (= ?a ?b))))
    :effect (and (at end (linked ?a ?b))))
  (:durative-action mark
    :parameters (?a ?b - item)
    :duration (= ?duration 1)
    :condition (and (at start (= ?a ?b)))
    :effect (and (at end (marked ?a)))))
"""

EQUALITY_PROBLEM = """
(define (problem equality1)
  (:domain equality)
  (:objects i1 i2 i3 - item)
  (:init)
  (:goal (and (linked i1 i2) (linked i3 i1) (marked i2))))
"""


def test_equality_and_inequality(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, EQUALITY, EQUALITY_PROBLEM)
    assert "mark i2 i2" in {a.name for a in planned.plan.actions}
    domain = parse_domain(EQUALITY)
    task = ground(domain, parse_problem(EQUALITY_PROBLEM, domain))
    for action in task.actions:
        kind, a, b = action.name.split()
        assert (a == b) == (kind == "mark")
    assert len(task.actions) == 6 + 3
    assert planned.plan.makespan < 1.0 + 10 * EPSILON  # all independent


# -- numeric fluents ------------------------------------------------------------------

NUMERIC = """
(define (domain numeric)
  (:requirements :typing :durative-actions :numeric-fluents)
  (:types truck city)
  (:predicates (at ?t - truck ?c - city))
  (:functions (fuel ?t - truck) (capacity ?t - truck) (distance ?a ?b - city)
              (speed ?t - truck) (trips))
  (:durative-action drive
    :parameters (?t - truck ?a ?b - city)
    :duration (= ?duration (/ (distance ?a ?b) (speed ?t)))
    :condition (and (at start (at ?t ?a))
                    (at start (>= (fuel ?t) (distance ?a ?b)))
                    (at start (> (distance ?a ?b) 0)))
    :effect (and (at start (not (at ?t ?a)))
                 (at start (decrease (fuel ?t) (distance ?a ?b)))
                 (at end (at ?t ?b))
                 (at end (increase (trips) 1))))
  (:durative-action refuel
    :parameters (?t - truck ?c - city)
    :duration (= ?duration (* 0.5 (- (capacity ?t) (fuel ?t))))
    :condition (and (over all (at ?t ?c))
                    (at start (< (fuel ?t) (capacity ?t))))
    :effect (and (at end (assign (fuel ?t) (capacity ?t))))))
"""

NUMERIC_PROBLEM = """
(define (problem numeric1)
  (:domain numeric)
  (:objects t1 - truck a b c - city)
  (:init (at t1 a) (= (fuel t1) 8) (= (capacity t1) 10) (= (speed t1) 2) (= (trips) 0)
         (= (distance a b) 6) (= (distance b c) 6) (= (distance a c) 20)
         (= (distance b a) 6) (= (distance c b) 6) (= (distance c a) 20)
         (= (distance a a) 0) (= (distance b b) 0) (= (distance c c) 0))
  (:goal (and (at t1 c) (<= (trips) 2))))
"""


def test_numeric_fluents_and_computed_durations(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, NUMERIC, NUMERIC_PROBLEM)
    names = [a.name for a in planned.plan.actions]
    # 8 fuel: a->b costs 6, so the truck refuels at b (2 left, 10 - 2 = 8 to fill)
    assert names == ["drive t1 a b", "refuel t1 b", "drive t1 b c"]
    durations = [a.duration for a in planned.plan.actions]
    assert durations == [pytest.approx(3.0), pytest.approx(4.0), pytest.approx(3.0)]


def test_numeric_goal_is_reached(tmp_path: Path) -> None:
    problem = NUMERIC_PROBLEM.replace("(<= (trips) 2)", "(>= (trips) 3)")
    planned = plan_and_validate(tmp_path, NUMERIC, problem)
    assert len(planned.named("drive")) >= 3


# -- duration inequalities ------------------------------------------------------------

DURATIONS = """
(define (domain durations)
  (:requirements :durative-actions :duration-inequalities)
  (:predicates (fixed) (bounded) (short) (long))
  (:durative-action exact
    :parameters ()
    :duration (= ?duration 2.5)
    :condition (and)
    :effect (and (at end (fixed))))
  (:durative-action window
    :parameters ()
    :duration (and (>= ?duration 2) (<= ?duration 5))
    :condition (and)
    :effect (and (at end (bounded))))
  (:durative-action quick
    :parameters ()
    :duration (<= ?duration 3)
    :condition (and)
    :effect (and (at end (short))))
  (:durative-action slow
    :parameters ()
    :duration (>= ?duration 4)
    :condition (and)
    :effect (and (at end (long)))))
"""

DURATIONS_PROBLEM = """
(define (problem durations1)
  (:domain durations)
  (:init)
  (:goal (and (fixed) (bounded) (short) (long))))
"""


def test_duration_constraints(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, DURATIONS, DURATIONS_PROBLEM)
    duration = {a.name: a.duration for a in planned.plan.actions}
    assert duration["exact"] == pytest.approx(2.5)
    assert 2.0 - TOL <= duration["window"] <= 5.0 + TOL
    assert 0.0 < duration["quick"] <= 3.0 + TOL
    assert duration["slow"] >= 4.0 - TOL
    assert planned.plan.makespan < 4.0 + 10 * EPSILON  # all four run together


# -- timed initial literals -----------------------------------------------------------

TIL = """
(define (domain shop)
  (:requirements :typing :durative-actions :timed-initial-literals)
  (:types person)
  (:predicates (open) (home ?p - person) (at-shop ?p - person) (has-bread ?p - person))
  (:durative-action walk
    :parameters (?p - person)
    :duration (= ?duration 1)
    :condition (and (at start (home ?p)))
    :effect (and (at start (not (home ?p))) (at end (at-shop ?p))))
  (:durative-action buy
    :parameters (?p - person)
    :duration (= ?duration 2)
    :condition (and (at start (at-shop ?p)) (over all (open)))
    :effect (and (at end (has-bread ?p)))))
"""

TIL_PROBLEM = """
(define (problem shop1)
  (:domain shop)
  (:objects ann - person)
  (:init (home ann) (at 5 (open)) (at 10 (not (open))))
  (:goal (and (has-bread ann))))
"""


def test_timed_initial_literals_window(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, TIL, TIL_PROBLEM)
    start = planned.start_of("buy")
    assert 5.0 < start <= 8.0  # the shop opens at 5 and closes at 10
    assert start < 5.0 + 10 * EPSILON  # and bread is bought as soon as it opens


def test_timed_initial_literals_window_too_short() -> None:
    problem = TIL_PROBLEM.replace("(at 10 (not (open)))", "(at 6.5 (not (open)))")
    assert status_of(TIL, problem) == "unsolvable"


# -- forall and conditional effects ---------------------------------------------------

CONDITIONAL = """
(define (domain conditional)
  (:requirements :typing :durative-actions :conditional-effects
                 :universal-preconditions :negative-preconditions :numeric-fluents)
  (:types block)
  (:predicates (dirty ?b - block) (clean ?b - block) (wet ?b - block) (ready))
  (:functions (washed))
  (:action prepare
    :parameters ()
    :precondition (forall (?b - block) (not (wet ?b)))
    :effect (and (ready)
                 (forall (?b - block) (when (dirty ?b) (wet ?b)))))
  (:durative-action wash-all
    :parameters ()
    :duration (= ?duration 3)
    :condition (and (at start (ready)))
    :effect (and (at start (not (ready)))
                 (at end (forall (?b - block)
                   (when (wet ?b) (and (clean ?b) (not (dirty ?b)) (not (wet ?b))
                                       (increase (washed) 1))))))))
"""

CONDITIONAL_PROBLEM = """
(define (problem conditional1)
  (:domain conditional)
  (:objects b1 b2 b3 - block)
  (:init (dirty b1) (dirty b2) (= (washed) 0))
  (:goal (and (clean b1) (clean b2) (not (clean b3)) (= (washed) 2)
              (forall (?b - block) (not (dirty ?b))))))
"""


def test_forall_and_conditional_effects(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, CONDITIONAL, CONDITIONAL_PROBLEM)
    # one wash cleans every dirty block at once, thanks to forall + when
    assert [a.name for a in planned.plan.actions] == ["prepare", "wash-all"]


# -- instantaneous and durative actions together --------------------------------------

MIXED = """
(define (domain mixed)
  (:requirements :durative-actions)
  (:predicates (power) (hot) (served))
  (:action switch-on
    :parameters ()
    :precondition (and (not (power)))
    :effect (power))
  (:durative-action heat
    :parameters ()
    :duration (= ?duration 4)
    :condition (and (over all (power)))
    :effect (and (at end (hot))))
  (:action serve
    :parameters ()
    :precondition (and (hot))
    :effect (served)))
"""

MIXED_PROBLEM = """
(define (problem mixed1)
  (:domain mixed)
  (:init)
  (:goal (and (served))))
"""


def test_instantaneous_and_durative_actions(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, MIXED, MIXED_PROBLEM)
    actions = planned.plan.actions
    assert [a.name for a in actions] == ["switch-on", "heat", "serve"]
    assert [a.duration is None for a in actions] == [True, False, True]
    assert planned.plan.makespan < 4.0 + 10 * EPSILON


# -- required concurrency (match cellar) ----------------------------------------------

MATCHES = """
(define (domain cellar)
  (:requirements :typing :durative-actions)
  (:types match fuse)
  (:predicates (handfree) (unused ?m - match) (mended ?f - fuse) (light ?m - match))
  (:durative-action light-match
    :parameters (?m - match)
    :duration (= ?duration 5)
    :condition (and (at start (unused ?m)))
    :effect (and (at start (not (unused ?m))) (at start (light ?m))
                 (at end (not (light ?m)))))
  (:durative-action mend-fuse
    :parameters (?f - fuse ?m - match)
    :duration (= ?duration 2)
    :condition (and (at start (handfree)) (over all (light ?m)))
    :effect (and (at start (not (handfree))) (at end (mended ?f)) (at end (handfree)))))
"""

MATCHES_PROBLEM = """
(define (problem cellar1)
  (:domain cellar)
  (:objects m1 m2 - match f1 f2 f3 - fuse)
  (:init (handfree) (unused m1) (unused m2))
  (:goal (and (mended f1) (mended f2) (mended f3))))
"""


def test_required_concurrency(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, MATCHES, MATCHES_PROBLEM)
    lights = {a.name.split()[1]: a for a in planned.plan.actions if a.name.startswith("light")}
    mends = [a for a in planned.plan.actions if a.name.startswith("mend")]
    assert len(mends) == 3
    for mend in mends:
        match = lights[mend.name.split()[2]]
        assert match.duration is not None and mend.duration is not None
        assert match.time < mend.time
        assert mend.time + mend.duration < match.time + match.duration


def test_required_concurrency_dead_end_is_seen_early() -> None:
    """Two matches burn 5 units each; three 2-unit mends fit, but not on one match.

    The search must notice as soon as a third mend is started under the same match
    that the match's end can no longer come in time.
    """
    result = solve(MATCHES, MATCHES_PROBLEM)
    assert result.status == "solved"
    assert result.stats.expanded < 200


@pytest.mark.parametrize("strategy", ["ehc", "bfs", "ff", "auto"])
def test_strategies_agree_on_validity(tmp_path: Path, strategy: str) -> None:
    planned = plan_and_validate(
        tmp_path, DURATIVE, DURATIVE_PROBLEM, strategy=strategy, name=strategy
    )
    assert len(planned.plan) == 2


def test_anytime_plans_are_valid_and_improve(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, MATCHES, MATCHES_PROBLEM, anytime=True)
    spans = [span for _, span in planned.result.improvements]
    assert spans == sorted(spans, reverse=True)
    assert planned.plan.makespan == pytest.approx(spans[-1])
