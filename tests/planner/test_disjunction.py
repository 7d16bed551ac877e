"""Disjunctive conditions: `or`, `imply`, `exists`, negated compound conditions, goals
and conditional effects with them, and conditional effects across times.

Every plan is validated by Kairos (in `plan_and_validate`); Kairos 1.0.6 supports all of
these constructs (`kairos --features`: disjunctive and existential preconditions,
conditional effects), including a durative action's `when` whose condition is at start
and effect at end. Each construct also has a problem that only the disjunction makes
solvable or unsolvable, so a planner that ignored it would fail the test.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from planning import EPSILON, plan_and_validate, solve, status_of

from cbdi_planner.dnf import MAX_DISJUNCTS
from cbdi_planner.errors import PlanInvalid, UnsupportedFeature
from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.pddl.ast import INST, Atom, Compare, FHead, Lit, Num, OrCond
from cbdi_planner.plan import Plan
from cbdi_planner.simulate import validate
from cbdi_planner.task import Task


def _task(domain_text: str, problem_text: str) -> Task:
    domain = parse_domain(domain_text, "domain.pddl")
    return ground(domain, parse_problem(problem_text, domain, "problem.pddl"))


def _where(text: str, needle: str) -> tuple[int, int]:
    """Return the 1-based line and column of `needle` in `text`."""
    before = text[: text.index(needle)]
    return before.count("\n") + 1, len(before) - before.rfind("\n")


def _names(plan: Plan) -> list[str]:
    return [a.name for a in plan.actions]


# -- reading: negation pushed to the literals -----------------------------------------


def test_negation_is_pushed_to_the_literals() -> None:
    text = """(define (domain n) (:requirements :adl :numeric-fluents)
          (:predicates (p) (q) (r)) (:functions (f))
          (:action a :parameters ()
            :precondition (not (or (p) (and (q) (not (r))) (= (f) 3) (imply (p) (q))))
            :effect (r)))"""
    domain = parse_domain(text)
    p, q, r = (Atom(name, ()) for name in "pqr")
    f = FHead("f", ())
    assert domain.actions[0].conditions == (
        Lit(p, False, INST),
        OrCond(((Lit(q, False, INST),), (Lit(r, True, INST),)), *_where(text, "(and (q)")),
        OrCond(
            ((Compare("<", f, Num(3), INST),), (Compare(">", f, Num(3), INST),)),
            *_where(text, "(= (f) 3)"),
        ),
        Lit(p, True, INST),  # not (imply p q) is p and not q
        Lit(q, False, INST),
    )


# -- or, imply, not over and in preconditions -----------------------------------------

DOOR = """
(define (domain door)
  (:requirements :strips :negative-preconditions :disjunctive-preconditions)
  (:predicates (has-key) (door-open) (inside) (raining) (umbrella) (busy) (locked))
  (:action open-door :parameters () :precondition (not (door-open))
    :effect (door-open))
  (:action unlock :parameters () :precondition (locked) :effect (not (locked)))
  (:action take-umbrella :parameters () :precondition (not (umbrella))
    :effect (umbrella))
  (:action enter :parameters ()
    :precondition (and (or (has-key) (door-open))
                       (imply (raining) (umbrella))
                       (not (and (busy) (locked))))
    :effect (inside)))
"""


def _door_problem(init: str) -> str:
    return f"(define (problem p) (:domain door) (:init {init}) (:goal (inside)))"


def test_or_takes_the_disjunct_that_holds(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, DOOR, _door_problem("(has-key)"))
    assert _names(planned.plan) == ["enter"]  # the key is enough: the door stays shut


def test_or_achieves_a_disjunct_when_none_holds(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, DOOR, _door_problem(""))
    assert _names(planned.plan) == ["open-door", "enter"]


def test_imply_needs_its_conclusion_only_under_its_premise(tmp_path: Path) -> None:
    dry = plan_and_validate(tmp_path, DOOR, _door_problem("(has-key)"), name="dry")
    wet = plan_and_validate(tmp_path, DOOR, _door_problem("(has-key) (raining)"), name="wet")
    assert "take-umbrella" not in _names(dry.plan)
    assert _names(wet.plan) == ["take-umbrella", "enter"]


def test_not_over_and_is_de_morgan(tmp_path: Path) -> None:
    planned = plan_and_validate(tmp_path, DOOR, _door_problem("(has-key) (busy) (locked)"))
    assert _names(planned.plan) == ["unlock", "enter"]  # not (busy and locked)
    easy = plan_and_validate(tmp_path, DOOR, _door_problem("(has-key) (busy)"), name="easy")
    assert _names(easy.plan) == ["enter"]


def test_infeasible_only_because_of_the_disjunction() -> None:
    # the door no longer opens: without a key, no disjunct of `enter` can ever hold
    no_door = DOOR.replace(":effect (door-open))", ":effect (umbrella))")
    assert status_of(no_door, _door_problem("")) == "unsolvable"
    assert status_of(no_door, _door_problem("(has-key)")) == "solved"


# -- exists, not forall, not exists ---------------------------------------------------

ROBOTS = """
(define (domain robots)
  (:requirements :typing :negative-preconditions :existential-preconditions
                 :universal-preconditions)
  (:types robot room)
  (:predicates (at ?r - robot ?x - room) (charged ?r - robot) (adjacent ?x ?y - room)
               (inspected ?x - room) (alarm ?x - room) (sealed ?x - room))
  (:action charge :parameters (?r - robot) :precondition (not (charged ?r))
    :effect (charged ?r))
  (:action move :parameters (?r - robot ?x ?y - room)
    :precondition (and (at ?r ?x) (adjacent ?x ?y))
    :effect (and (not (at ?r ?x)) (at ?r ?y)))
  (:action inspect :parameters (?x - room)
    :precondition (exists (?r - robot) (and (at ?r ?x) (charged ?r)))
    :effect (inspected ?x))
  (:action seal :parameters (?x - room)
    :precondition (and (not (forall (?r - robot) (not (at ?r ?x))))
                       (not (exists (?y - room) (and (adjacent ?x ?y) (alarm ?y)))))
    :effect (sealed ?x)))
"""


def _robots_problem(init: str, goal: str) -> str:
    return f"""
(define (problem p) (:domain robots)
  (:objects r1 r2 - robot a b c - room)
  (:init (adjacent a b) (adjacent b a) (adjacent b c) (adjacent c b) {init})
  (:goal {goal}))
"""


def test_exists_picks_a_witness(tmp_path: Path) -> None:
    init = "(at r1 a) (at r2 c) (charged r1)"
    planned = plan_and_validate(tmp_path, ROBOTS, _robots_problem(init, "(inspected c)"))
    names = _names(planned.plan)
    # r2 is in c already: charging it is shorter than bringing r1 over
    assert names == ["charge r2", "inspect c"]


def test_exists_with_no_possible_witness_is_unsolvable() -> None:
    problem = _robots_problem("(charged r1)", "(inspected c)")  # no robot anywhere
    assert status_of(ROBOTS, problem) == "unsolvable"


def test_not_forall_and_not_exists(tmp_path: Path) -> None:
    init = "(at r1 a) (alarm c)"
    planned = plan_and_validate(tmp_path, ROBOTS, _robots_problem(init, "(sealed a)"))
    assert _names(planned.plan) == ["seal a"]  # a robot in a, no alarm next to a
    assert status_of(ROBOTS, _robots_problem(init, "(sealed b)")) == "unsolvable"  # c rings
    moved = plan_and_validate(
        tmp_path, ROBOTS, _robots_problem("(at r1 a)", "(sealed c)"), name="moved"
    )
    assert _names(moved.plan)[-1] == "seal c"  # not forall not: some robot must get to c


# -- disjunctive goals ----------------------------------------------------------------

LIGHTS = """
(define (domain lights)
  (:requirements :strips :disjunctive-preconditions)
  (:predicates (light) (door-open) (done))
  (:action switch-on :parameters () :precondition (not (light)) :effect (light))
  (:action open-door :parameters () :precondition (not (door-open)) :effect (door-open))
  (:action work :parameters () :precondition (light)
    :effect (and (done) (not (light)))))
"""

LIGHTS_PROBLEM = """
(define (problem p) (:domain lights) (:init)
  (:goal (and (done) (or (light) (door-open)))))
"""


def test_disjunctive_goal_holds_at_the_end(tmp_path: Path) -> None:
    """`work` turns the light off: a disjunct that held before it does not count."""
    planned = plan_and_validate(tmp_path, LIGHTS, LIGHTS_PROBLEM)
    names = _names(planned.plan)
    assert names[:2] == ["switch-on", "work"] and len(names) == 3
    assert not any(n.startswith("#") for n in names)  # the internal goal actions
    task = _task(LIGHTS, LIGHTS_PROBLEM)
    assert validate(task, planned.plan).goal_reached  # our own simulator agrees
    with pytest.raises(PlanInvalid, match="without reaching the goal"):
        validate(task, Plan(planned.plan.actions[:2]))


def test_disjunctive_goal_already_true_needs_no_action(tmp_path: Path) -> None:
    problem = LIGHTS_PROBLEM.replace("(:init)", "(:init (done) (door-open))")
    result = solve(LIGHTS, problem)
    assert result.plan is not None and len(result.plan) == 0


def test_disjunctive_goal_through_the_cli(tmp_path: Path) -> None:
    (tmp_path / "d.pddl").write_text(LIGHTS)
    (tmp_path / "p.pddl").write_text(LIGHTS_PROBLEM)
    done = subprocess.run(
        [sys.executable, "-m", "cbdi_planner.cli", "plan", "d.pddl", "p.pddl"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "(work)" in done.stdout and "#" not in done.stdout


def test_unsatisfiable_disjunctive_goal() -> None:
    problem = LIGHTS_PROBLEM.replace("(or (light) (door-open))", "(or (light) (light))")
    problem = problem.replace("(done)", "(done) (not (light))")
    assert status_of(LIGHTS, problem) == "unsolvable"


# -- or inside when, with a numeric effect ---------------------------------------------

SCORE = """
(define (domain score)
  (:requirements :strips :conditional-effects :numeric-fluents :disjunctive-preconditions)
  (:predicates (red) (big) (ticked) (flagged))
  (:functions (score))
  (:action paint :parameters () :precondition (not (red)) :effect (red))
  (:action shrink :parameters () :precondition (big) :effect (not (big)))
  (:action tick :parameters () :precondition (not (ticked))
    :effect (and (ticked)
                 (when (or (red) (big)) (and (increase (score) 1) (flagged))))))
"""


def _score_problem(init: str, goal: str) -> str:
    return f"""
(define (problem p) (:domain score) (:init {init} (= (score) 0))
  (:goal (and (ticked) {goal})))
"""


def test_numeric_effect_under_or_happens_once(tmp_path: Path) -> None:
    both = _score_problem("(red) (big)", "(flagged) (= (score) 1)")
    plan_and_validate(tmp_path, SCORE, both)
    # counted twice, the score would be 2 and this goal reachable
    assert status_of(SCORE, _score_problem("(red) (big)", "(>= (score) 2)")) == "unsolvable"
    one = plan_and_validate(tmp_path, SCORE, _score_problem("(big)", "(= (score) 1)"), name="one")
    assert _names(one.plan) == ["tick"]
    none = plan_and_validate(tmp_path, SCORE, _score_problem("", "(flagged)"), name="none")
    assert _names(none.plan) == ["paint", "tick"]  # makes a disjunct of the `when` true


# -- durative actions: disjunctions at start, over all, at end -----------------------

INSPECT = """
(define (domain inspect)
  (:requirements :typing :durative-actions :disjunctive-preconditions
                 :timed-initial-literals)
  (:types room)
  (:predicates (light ?x - room) (lamp) (at ?x - room) (seen ?x - room) (free))
  (:durative-action fetch-lamp :parameters () :duration (= ?duration 2)
    :condition (at start (free))
    :effect (and (at start (not (free))) (at end (free)) (at end (lamp))))
  (:action unscrew :parameters (?x - room) :precondition (light ?x)
    :effect (not (light ?x)))
  (:durative-action inspect :parameters (?x - room) :duration (= ?duration 3)
    :condition (and (at start (or (at ?x) (light ?x)))
                    (over all (or (light ?x) (lamp)))
                    (at end (or (free) (lamp))))
    :effect (at end (seen ?x))))
"""


def _inspect_problem(init: str, goal: str = "(seen r1)") -> str:
    return f"""
(define (problem p) (:domain inspect) (:objects r1 r2 - room)
  (:init (free) {init}) (:goal (and {goal})))
"""


def test_over_all_disjunction(tmp_path: Path) -> None:
    lit = plan_and_validate(tmp_path, INSPECT, _inspect_problem("(light r1)"), name="lit")
    assert _names(lit.plan) == ["inspect r1"]
    dark = plan_and_validate(tmp_path, INSPECT, _inspect_problem("(at r1)"), name="dark")
    assert _names(dark.plan) == ["fetch-lamp", "inspect r1"]  # the lamp keeps it lit
    (fetch,) = dark.named("fetch-lamp")
    assert dark.start_of("inspect") >= fetch[0] + 2.0 - 1e-6


def test_over_all_disjunction_holds_through_a_timed_literal(tmp_path: Path) -> None:
    """The light goes out at 1: only the lamp can keep the room lit for 3 time units."""
    problem = _inspect_problem("(light r1) (at r1) (at 1 (not (light r1)))")
    planned = plan_and_validate(tmp_path, INSPECT, problem)
    assert _names(planned.plan) == ["fetch-lamp", "inspect r1"]
    assert planned.start_of("inspect") >= 2.0 - 1e-6
    assert status_of(INSPECT.replace("(at end (lamp))", ""), problem) == "unsolvable"


def test_durative_split_actions_share_one_name_and_never_overlap(tmp_path: Path) -> None:
    problem = _inspect_problem("(at r1) (light r1) (light r2)", "(seen r1) (seen r2)")
    task = _task(INSPECT, problem)
    copies = [a for a in task.actions if a.name == "inspect r1"]
    assert len(copies) > 1
    assert any(f.startswith("(#running inspect r1") for f in task.facts)
    planned = plan_and_validate(tmp_path, INSPECT, problem)
    assert sorted(_names(planned.plan)) == ["inspect r1", "inspect r2"]
    assert planned.plan.makespan < 3.0 + 10 * EPSILON  # the two run together


# -- conditional effects across times -------------------------------------------------

PAINT = """
(define (domain paint)
  (:requirements :typing :durative-actions :conditional-effects :numeric-fluents)
  (:types item)
  (:predicates (wet ?x - item) (dry ?x - item) (done ?x - item) (sunny))
  (:functions (ruined))
  (:durative-action paint :parameters (?x - item) :duration (= ?duration 2)
    :condition (at start (not (done ?x)))
    :effect (and (at start (not (dry ?x))) (at start (wet ?x)) (at end (done ?x))
                 (when (at start (wet ?x)) (at end (increase (ruined) 1)))
                 (at end (when (and (at start (dry ?x)) (sunny)) (dry ?x))))))
"""


def _paint_problem(init: str, goal: str) -> str:
    return f"""
(define (problem p) (:domain paint) (:objects a b - item)
  (:init {init} (= (ruined) 0)) (:goal (and {goal})))
"""


def test_when_at_start_effect_at_end(tmp_path: Path) -> None:
    """The start condition is read before the start effects (which make `a` wet)."""
    clean = _paint_problem("(dry a) (sunny)", "(done a) (dry a) (= (ruined) 0)")
    planned = plan_and_validate(tmp_path, PAINT, clean)
    assert _names(planned.plan) == ["paint a"]
    wet = _paint_problem("(wet b)", "(done b) (>= (ruined) 1)")
    plan_and_validate(tmp_path, PAINT, wet, name="wet")
    # dry at start but not sunny at end: the end condition is part of it too
    assert status_of(PAINT, _paint_problem("(dry a)", "(done a) (dry a)")) == "unsolvable"
    # dry a was never wet: nothing is ruined
    never_wet = _paint_problem("(dry a)", "(done a) (>= (ruined) 1)")
    assert status_of(PAINT, never_wet) == "unsolvable"


def test_cross_time_when_splits_by_the_start_condition() -> None:
    task = _task(PAINT, _paint_problem("(dry a) (sunny)", "(done a)"))
    copies = [a for a in task.actions if a.name == "paint a"]
    assert len(copies) == 4  # (wet a) held at start or not, times (dry a) did or not
    wet = 1 << task.facts.index("(wet a)")
    for copy in copies:
        assert copy.end is not None
        # only the copies that required (wet a) at start ruin anything at end
        assert bool(copy.start.pre & wet) == bool(copy.end.num_eff)
        assert bool(copy.start.neg & wet) == (not copy.end.num_eff)


# -- errors ---------------------------------------------------------------------------

BLOWUP = """(define (domain blowup)
  (:requirements :strips :disjunctive-preconditions)
  (:constants o1 o2 o3 o4 o5 o6 o7)
  (:predicates (p ?i) (q ?i) (done))
  (:action flip :parameters (?i) :precondition (not (p ?i))
    :effect (and (p ?i) (q ?i)))
  (:action go :parameters ()
    :precondition (and CONDITIONS)
    :effect (done)))
"""

BLOWUP_PROBLEM = """(define (problem p) (:domain blowup)
  (:init)
  (:goal (done)))
"""


def test_too_many_disjuncts_is_a_located_error() -> None:
    ors = " ".join(f"(or (p o{k}) (q o{k}))" for k in range(1, 8))  # 2**7 = 128
    text = BLOWUP.replace("CONDITIONS", ors)
    domain = parse_domain(text, "blowup.pddl")
    problem = parse_problem(BLOWUP_PROBLEM, domain, "problem.pddl")
    with pytest.raises(UnsupportedFeature) as info:
        ground(domain, problem)
    error = info.value
    # located at the `or` that took it past the limit, the seventh
    assert (error.file, error.line, error.column) == ("blowup.pddl", *_where(text, "(or (p o7)"))
    assert "128 disjuncts" in error.message and f"more than the {MAX_DISJUNCTS}" in error.message


def test_six_binary_ors_are_fine(tmp_path: Path) -> None:
    ors = " ".join(f"(or (p o{k}) (q o{k}))" for k in range(1, 7))  # 2**6 = 64
    planned = plan_and_validate(tmp_path, BLOWUP.replace("CONDITIONS", ors), BLOWUP_PROBLEM)
    assert _names(planned.plan)[-1] == "go"


def test_too_many_goal_disjuncts_points_at_the_problem() -> None:
    domain = parse_domain(BLOWUP.replace("CONDITIONS", ""), "blowup.pddl")
    goal = " ".join(f"(or (p o{k}) (q o{k}))" for k in range(1, 8))
    problem_text = BLOWUP_PROBLEM.replace("(:goal (done))", f"(:goal (and {goal}))")
    problem = parse_problem(problem_text, domain, "problem.pddl")
    with pytest.raises(UnsupportedFeature) as info:
        ground(domain, problem)
    where = ("problem.pddl", *_where(problem_text, "(or (p o7)"))
    assert (info.value.file, info.value.line, info.value.column) == where
    assert "the goal" in info.value.message


def test_exists_over_too_many_objects_is_a_located_error() -> None:
    text = BLOWUP.replace("CONDITIONS", "(exists (?i) (p ?i))")
    objects = " ".join(f"x{k}" for k in range(MAX_DISJUNCTS))  # with o1..o7: past the limit
    problem_text = BLOWUP_PROBLEM.replace("(:init)", f"(:objects {objects}) (:init)")
    domain = parse_domain(text, "blowup.pddl")
    with pytest.raises(UnsupportedFeature) as info:
        ground(domain, parse_problem(problem_text, domain, "problem.pddl"))
    assert (info.value.line, info.value.column) == _where(text, "(exists")


def test_unsupported_when_across_times_is_located() -> None:
    over_all = PAINT.replace("(when (at start (wet ?x))", "(when (over all (wet ?x))")
    domain = parse_domain(over_all, "paint.pddl")
    problem = parse_problem(_paint_problem("(dry a)", "(done a)"), domain, "problem.pddl")
    with pytest.raises(UnsupportedFeature) as info:
        ground(domain, problem)
    where = ("paint.pddl", *_where(over_all, "(when (over all"))
    assert (info.value.file, info.value.line, info.value.column) == where
    assert "effect at end whose condition is checked over all" in info.value.message


def test_end_condition_on_a_start_effect_is_unsupported() -> None:
    text = PAINT.replace(
        "(when (at start (wet ?x)) (at end (increase (ruined) 1)))",
        "(when (at end (wet ?x)) (at start (increase (ruined) 1)))",
    )
    domain = parse_domain(text, "paint.pddl")
    with pytest.raises(UnsupportedFeature) as info:
        ground(domain, parse_problem(_paint_problem("(dry a)", "(done a)"), domain, "p.pddl"))
    assert (info.value.line, info.value.column) == _where(text, "(when (at end")
