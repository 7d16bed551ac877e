"""IPC temporal benchmarks (unmodified, from /work/shared): plans Kairos accepts.

The problems listed are those the planner solves within about a second, from every
domain; the slower ones are left to `make bench-planner` (elevator and depots p03 are
in `test_compression.py`).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from planning import EPSILON, validate

from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.search import Budget, search

BENCHMARKS = Path(os.environ.get("CBDI_TEMPORAL_BENCHMARKS", "/work/shared/benchmarks/temporal"))

SOLVED = [
    ("matchcellar", "p01"),
    ("matchcellar", "p02"),
    ("printingfloor", "p01"),
    ("driverlog", "p01"),
    ("driverlog", "p02"),
    ("depots", "p01"),
    ("depots", "p02"),
    ("zenotravel", "p01"),
    ("zenotravel", "p02"),
    ("zenotravel", "p08"),
    ("driverlog", "p08"),
    ("matchcellar", "p03"),
    ("parking", "p03"),
    ("crewplanning", "p01"),
    ("crewplanning", "p02"),
    ("crewplanning", "p03"),
    ("crewplanning", "p04"),
    ("crewplanning", "p05"),
]


@pytest.mark.parametrize(("domain_name", "problem_name"), SOLVED)
def test_ipc_problem(tmp_path: Path, domain_name: str, problem_name: str) -> None:
    folder = BENCHMARKS / domain_name
    domain_file, problem_file = folder / "domain.pddl", folder / f"{problem_name}.pddl"
    if not problem_file.exists():
        pytest.skip(f"benchmark {problem_file} is not available")
    domain = parse_domain(domain_file.read_text(), str(domain_file))
    problem = parse_problem(problem_file.read_text(), domain, str(problem_file))
    result = search(ground(domain, problem), budget=Budget(max_seconds=15), epsilon=EPSILON)
    assert result.status == "solved" and result.plan is not None, result.stats
    plan_file = tmp_path / "plan.txt"
    plan_file.write_text(result.plan.to_ipc())
    valid, output = validate(domain_file, problem_file, plan_file)
    assert valid, f"kairos rejects the plan:\n{result.plan.to_ipc()}\n{output}"


def test_required_concurrency_is_respected_in_matchcellar(tmp_path: Path) -> None:
    folder = BENCHMARKS / "matchcellar"
    if not folder.exists():
        pytest.skip("matchcellar benchmark is not available")
    domain = parse_domain((folder / "domain.pddl").read_text())
    problem = parse_problem((folder / "p01.pddl").read_text(), domain)
    result = search(ground(domain, problem), budget=Budget(max_seconds=15))
    assert result.plan is not None
    lights = {a.name.split()[1]: a for a in result.plan.actions if a.name.startswith("light")}
    for mend in (a for a in result.plan.actions if a.name.startswith("mend")):
        light = lights[mend.name.split()[2]]
        assert light.duration is not None and mend.duration is not None
        assert light.time < mend.time < mend.time + mend.duration < light.time + light.duration
