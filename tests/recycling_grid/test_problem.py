"""`cbdi problem`: a map becomes a PDDL problem that cbdi's planner solves and kairos accepts."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from cbdi_recycling.errors import MapError
from cbdi_recycling.maps import load_map, parse_map
from cbdi_recycling.problem import main, problem_text

ROOT = Path(__file__).resolve().parents[2]
DOMAIN = ROOT / "domains/recycling/pddl/domain.pddl"
MAPS = sorted((ROOT / "domains/recycling/maps").glob("*.toml"))
BIN = Path(sys.executable).parent


@pytest.mark.parametrize("name", ["paper-7x7", "warehouse-15x15", "campus-30x30"])
def test_the_checked_in_problems_are_what_the_generator_writes(name: str) -> None:
    text = problem_text(load_map(ROOT / f"domains/recycling/maps/{name}.toml"))
    stored = (ROOT / f"domains/recycling/problems/{name}.pddl").read_text()
    assert text.splitlines()[1:] == stored.splitlines()[1:]  # line 1 names the source


@pytest.mark.parametrize("path", [m for m in MAPS if "campus" not in m.name], ids=lambda p: p.stem)
def test_every_map_gives_a_problem_with_a_valid_plan(path: Path, tmp_path: Path) -> None:
    problem = tmp_path / "problem.pddl"
    assert main([str(path), "-o", str(problem)]) == 0
    plan = tmp_path / "plan.txt"
    done = subprocess.run(
        [
            str(BIN / "cbdi-planner"),
            "plan",
            str(DOMAIN),
            str(problem),
            "-o",
            str(plan),
            "--timeout",
            "60",
        ],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    check = subprocess.run(
        [str(BIN / "kairos"), "validate", str(DOMAIN), str(problem), str(plan)],
        capture_output=True,
        text=True,
    )
    assert check.returncode == 0, check.stdout + check.stderr


def test_robots_and_known_litter() -> None:
    world_map = load_map(ROOT / "domains/recycling/maps/paper-7x7.toml")
    text = problem_text(world_map, robots=3)
    assert "(in robot3 c_3_2)" in text and "(free c_3_2)" not in text
    with pytest.raises(MapError, match="4 robots but the map has 3 start cells"):
        problem_text(world_map, robots=4)
    hidden = parse_map('name = "m"\ngrid = """\nBA.l\n"""\n')
    assert "(:goal (and ))" in problem_text(hidden, litter="known")
    assert "(recycled plastic_3_0)" in problem_text(hidden)
