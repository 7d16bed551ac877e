"""Bad input gives a located error of the right class; hopeless problems say so."""

from __future__ import annotations

import pytest
from planning import solve, status_of

from cbdi_planner.errors import (
    PddlError,
    PddlSyntaxError,
    SemanticError,
    Unsolvable,
    UnsupportedFeature,
)
from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.search import Budget

DOMAIN = """(define (domain d)
  (:requirements :typing :durative-actions)
  (:types thing)
  (:predicates (p ?x - thing) (q ?x ?y - thing))
  (:durative-action a
    :parameters (?x - thing)
    :duration (= ?duration 1)
    :condition (and (at start (p ?x)))
    :effect (and (at end (not (p ?x))))))
"""

PROBLEM = """(define (problem pr)
  (:domain d)
  (:objects o1 o2 - thing)
  (:init (p o1))
  (:goal (and (not (p o1)))))
"""


def test_the_fixtures_are_fine() -> None:
    assert solve(DOMAIN, PROBLEM).status == "solved"


def _domain_error(text: str) -> PddlError:
    with pytest.raises(PddlError) as info:
        parse_domain(text, "dom.pddl")
    return info.value


def _problem_error(text: str) -> PddlError:
    domain = parse_domain(DOMAIN, "dom.pddl")
    with pytest.raises(PddlError) as info:
        parse_problem(text, domain, "prob.pddl")
    return info.value


def _at(error: PddlError, kind: type[PddlError], file: str, line: int, column: int) -> None:
    assert type(error) is kind, error
    assert (error.file, error.line, error.column) == (file, line, column), str(error)
    assert str(error).startswith(f"{file}:{line}:{column}: ")


# -- domain ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "kind", "line", "column", "words"),
    [
        pytest.param(
            DOMAIN.rstrip()[:-1], PddlSyntaxError, 9, 41, "line 1, column 1", id="unclosed"
        ),
        pytest.param(DOMAIN + ")", PddlSyntaxError, 10, 1, "unexpected ')'", id="extra-paren"),
        pytest.param(
            DOMAIN.replace("(:types thing)", "(:typez thing)"),
            PddlSyntaxError,
            3,
            3,
            "unknown domain section ':typez'",
            id="unknown-section",
        ),
        pytest.param(
            DOMAIN.replace(":condition", ":precondition"),
            PddlSyntaxError,
            8,
            19,
            "unexpected field :precondition",
            id="unknown-field",
        ),
        pytest.param(
            DOMAIN.replace(":requirements :typing", ":requirements :typnig"),
            PddlSyntaxError,
            2,
            18,
            "unknown requirement ':typnig'",
            id="unknown-requirement",
        ),
        pytest.param(
            DOMAIN.replace("(p ?x - thing)", "(p ?x - thang)"),
            SemanticError,
            4,
            19,
            "unknown type 'thang'",
            id="unknown-type",
        ),
        pytest.param(
            DOMAIN.replace("(at start (p ?x))", "(at start (r ?x))"),
            SemanticError,
            8,
            32,
            "unknown predicate 'r'",
            id="unknown-predicate",
        ),
        pytest.param(
            DOMAIN.replace("(at start (p ?x))", "(at start (q ?x))"),
            SemanticError,
            8,
            31,
            "'q' takes 2 argument(s), got 1",
            id="wrong-arity",
        ),
        pytest.param(
            DOMAIN.replace("(at start (p ?x))", "(at start (p ?y))"),
            SemanticError,
            8,
            34,
            "variable ?y",
            id="unknown-variable",
        ),
        pytest.param(
            DOMAIN.replace(":durative-actions)", ":durative-actions :continuous-effects)"),
            UnsupportedFeature,
            2,
            44,
            "requirement :continuous-effects",
            id="unsupported-requirement",
        ),
        pytest.param(
            DOMAIN.replace("(at start (p ?x))", "(p ?x)"),
            PddlSyntaxError,
            8,
            21,
            "untimed condition",
            id="untimed-condition",
        ),
    ],
)
def test_domain_errors(
    text: str, kind: type[PddlError], line: int, column: int, words: str
) -> None:
    error = _domain_error(text)
    _at(error, kind, "dom.pddl", line, column)
    assert words in error.message


# -- problem --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "kind", "line", "column", "words"),
    [
        pytest.param(
            PROBLEM.replace("(p o1))", "(p o1)"),
            PddlSyntaxError,
            6,
            1,
            "never closed",
            id="unclosed",
        ),
        pytest.param(
            PROBLEM.replace(":init", ":inits"),
            PddlSyntaxError,
            4,
            3,
            "unknown problem section ':inits'",
            id="unknown-section",
        ),
        pytest.param(
            PROBLEM.replace("o1 o2 - thing", "o1 o2 - thang"),
            SemanticError,
            3,
            13,
            "unknown type 'thang'",
            id="unknown-type",
        ),
        pytest.param(
            PROBLEM.replace("(:init (p o1))", "(:init (z o1))"),
            SemanticError,
            4,
            11,
            "unknown predicate 'z'",
            id="unknown-predicate",
        ),
        pytest.param(
            PROBLEM.replace("(:init (p o1))", "(:init (p o1 o2))"),
            SemanticError,
            4,
            10,
            "takes 1 argument(s), got 2",
            id="wrong-arity",
        ),
        pytest.param(
            PROBLEM.replace("(not (p o1))", "(not (p o3))"),
            SemanticError,
            5,
            23,
            "unknown object 'o3'",
            id="unknown-object",
        ),
        pytest.param(
            PROBLEM.replace("(:domain d)", "(:domain e)"),
            SemanticError,
            2,
            12,
            "not 'd'",
            id="wrong-domain",
        ),
    ],
)
def test_problem_errors(
    text: str, kind: type[PddlError], line: int, column: int, words: str
) -> None:
    error = _problem_error(text)
    _at(error, kind, "prob.pddl", line, column)
    assert words in error.message


def test_error_columns_count_tabs_and_comments_as_characters() -> None:
    text = DOMAIN.replace("(:types thing)", "; a comment (with parens\n\t(:types thang - thing)")
    text = text.replace("(p ?x - thing)", "(p ?x - thang)").replace("(:types thang", "(:types")
    error = _domain_error(text.replace("(p ?x - thang)", "(p ?x - thong)"))
    _at(error, SemanticError, "dom.pddl", 5, 19)


# -- hopeless problems ----------------------------------------------------------------

TRAP = """(define (domain trap)
  (:requirements :negative-preconditions)
  (:predicates (used) (x) (y))
  (:action make-x :parameters () :precondition (not (used)) :effect (and (used) (x)))
  (:action make-y :parameters () :precondition (not (used)) :effect (and (used) (y))))
"""

TRAP_PROBLEM = """(define (problem trap1)
  (:domain trap)
  (:init)
  (:goal (and (x) (y))))
"""


def test_unsolvable_by_search() -> None:
    # relaxed reachable (negative conditions are relaxed), so only search can tell
    for strategy in ("auto", "bfs"):
        assert solve(TRAP, TRAP_PROBLEM, strategy=strategy).status == "unsolvable"


def test_unsolvable_when_enforced_hill_climbing_gets_stuck_is_incomplete() -> None:
    assert solve(TRAP, TRAP_PROBLEM, strategy="ehc").status in ("incomplete", "unsolvable")


def test_unsolvable_at_grounding() -> None:
    problem = PROBLEM.replace("(not (p o1))", "(p o2)")  # nothing ever adds p
    domain = parse_domain(DOMAIN)
    with pytest.raises(Unsolvable):
        ground(domain, parse_problem(problem, domain))
    assert status_of(DOMAIN, problem) == "unsolvable"


def test_tiny_budget_times_out() -> None:
    text = """(define (problem cellar)
      (:domain cellar)
      (:objects m1 m2 m3 - match f1 f2 f3 f4 f5 - fuse)
      (:init (handfree) (unused m1) (unused m2) (unused m3))
      (:goal (and (mended f1) (mended f2) (mended f3) (mended f4) (mended f5))))"""
    from test_features import MATCHES

    result = solve(MATCHES, text, budget=Budget(max_expansions=3))
    assert result.status == "timeout"
    assert result.plan is None
    assert result.stats.expanded == 4  # the fourth expansion is refused


def test_time_budget_uses_the_injected_clock() -> None:
    from cbdi_planner.search import search

    domain = parse_domain(DOMAIN)
    task = ground(domain, parse_problem(PROBLEM.replace("(not (p o1))", "(p o1)"), domain))
    ticks = iter(range(1000))
    result = search(task, budget=Budget(max_seconds=0.5), now=lambda: float(next(ticks)))
    assert result.status in ("solved", "timeout")
