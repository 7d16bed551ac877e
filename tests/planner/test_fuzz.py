"""Broken PDDL gives a located error, never a crash (issue 15).

The shipped domain and problem are truncated and mutated with a fixed seed; every
variant either parses and grounds, or raises a `PlannerError`. Nesting too deep and
non-finite numbers are refused where they are written, and `cbdi plan` turns any of
it into a message and exit code 2, never a traceback.
"""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path

import pytest

from cbdi_planner.errors import PddlSyntaxError, PlanInvalid, PlannerError
from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.pddl.sexpr import MAX_DEPTH
from cbdi_planner.plan import parse_plan

ROOT = Path(__file__).resolve().parents[2]
DOMAIN = (ROOT / "domains/recycling/pddl/domain.pddl").read_text()
PROBLEM = (ROOT / "domains/recycling/problems/paper-7x7.pddl").read_text()
CBDI = Path(sys.executable).parent / "cbdi"


def mutate(text: str, rng: random.Random) -> str:
    """One random damage: truncate, delete, duplicate, insert nesting or a bad number."""
    i = rng.randrange(len(text))
    kind = rng.randrange(6)
    if kind == 0:
        return text[:i]
    if kind == 1:
        return text[:i] + text[i + rng.randint(1, 20) :]
    if kind == 2:
        return text[:i] + rng.choice("()?-: \n;") + text[i:]
    if kind == 3:
        depth = rng.choice((MAX_DEPTH - 5, MAX_DEPTH + 1, 500))
        return text[:i] + "(and " * depth + ")" * depth + text[i:]
    if kind == 4:
        j = rng.randrange(len(text))
        return text[:i] + text[j : j + rng.randint(1, 40)] + text[i:]
    return text.replace(" 1)", f" {rng.choice(('nan', 'inf', '-inf', '1e400', '1.2.3'))})", 1)


def parse_and_ground(domain_text: str, problem_text: str) -> None:
    domain = parse_domain(domain_text, "domain.pddl")
    ground(domain, parse_problem(problem_text, domain, "problem.pddl"))


@pytest.mark.parametrize("which", ["domain", "problem"])
def test_mutated_shipped_files_parse_or_give_a_planner_error(which: str) -> None:
    rng = random.Random(f"fuzz:{which}")
    errors = 0
    for _ in range(150):
        domain, problem = DOMAIN, PROBLEM
        if which == "domain":
            domain = mutate(DOMAIN, rng)
        else:
            problem = mutate(PROBLEM, rng)
        try:
            parse_and_ground(domain, problem)
        except PlannerError as exc:
            errors += 1
            assert str(exc)
    assert errors > 50  # the mutations do break the files


def test_nesting_too_deep_is_refused_where_it_opens() -> None:
    deep = "(define (problem p) (:domain recycling)\n (:goal " + "(and " * 500 + ")" * 502
    with pytest.raises(PddlSyntaxError) as err:
        parse_problem(deep, parse_domain(DOMAIN, "domain.pddl"), "deep.pddl")
    # (define is depth 1, (:goal 2: the (MAX_DEPTH - 1)th (and is one too many
    assert (err.value.line, err.value.column) == (2, 9 + 5 * (MAX_DEPTH - 2))
    assert f"nested more than {MAX_DEPTH} deep" in str(err.value)
    assert "deep.pddl:2:" in str(err.value)


@pytest.mark.parametrize("number", ["nan", "inf", "-inf", "1e400", "NaN"])
def test_non_finite_numbers_are_refused_with_their_place(number: str) -> None:
    durations = DOMAIN.replace("(= ?duration 1)", f"(= ?duration {number})", 1)
    assert durations != DOMAIN
    with pytest.raises(PddlSyntaxError, match=r"is not a finite number") as err:
        parse_domain(durations, "domain.pddl")
    assert err.value.line == DOMAIN[: DOMAIN.index("(= ?duration 1)")].count("\n") + 1
    initial = PROBLEM.replace(
        "(= (loaded_amount robot1) 0)", f"(= (loaded_amount robot1) {number})"
    )
    assert initial != PROBLEM
    with pytest.raises(PddlSyntaxError, match=r"is not a finite number"):
        parse_problem(initial, parse_domain(DOMAIN, "domain.pddl"), "problem.pddl")


def test_a_plan_with_non_finite_times_is_invalid() -> None:
    for line in ("1e400: (move robot1 c_1_1 c_1_2) [1]", "0: (move r a b) [nan]", "1.2.3: (m)"):
        with pytest.raises(PlanInvalid, match="plan line 1"):
            parse_plan(line)


def test_cbdi_plan_reports_a_bad_file_with_exit_2_and_no_traceback(tmp_path: Path) -> None:
    problem = tmp_path / "p.pddl"
    cases = {
        "deep": "(define (problem p) (:domain recycling) (:goal " + "(and " * 500 + ")" * 502,
        "nan": PROBLEM.replace("(= (loaded_amount robot1) 0)", "(= (loaded_amount robot1) nan)"),
        "truncated": PROBLEM[: len(PROBLEM) // 2],
    }
    for name, text in cases.items():
        problem.write_text(text)
        domain = ROOT / "domains/recycling/pddl/domain.pddl"
        done = subprocess.run(
            [str(CBDI), "plan", str(domain), str(problem)], capture_output=True, text=True
        )
        assert done.returncode == 2, (name, done.stderr)
        assert "Traceback" not in done.stderr and str(problem) in done.stderr, name
    problem.write_bytes(b"\xff\xfe(define")
    done = subprocess.run(
        [str(CBDI), "plan", str(domain), str(problem)], capture_output=True, text=True
    )
    assert done.returncode == 2 and "UTF-8" in done.stderr and "Traceback" not in done.stderr
