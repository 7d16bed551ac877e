"""The project's recycling domain: hand-made grids, the map files and random grids.

Problems are written here from a grid picture (`#` wall, `B` bin, `A` robot, `L`
litter, `.` free), the way the map files draw them; cells are `c_X_Y` with x the column
and y the row.
"""

from __future__ import annotations

import tomllib
from collections import deque
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from planning import plan_and_validate

ROOT = Path(__file__).resolve().parents[2]
DOMAIN = (ROOT / "domains/recycling/pddl/domain.pddl").read_text()
MAPS = ROOT / "domains/recycling/maps"

Cell = tuple[int, int]


def _cells(grid: str) -> dict[Cell, str]:
    rows = [row for row in grid.strip("\n").splitlines() if row.strip()]
    return {(x, y): ch for y, row in enumerate(rows) for x, ch in enumerate(row)}


def _name(cell: Cell) -> str:
    return f"c_{cell[0]}_{cell[1]}"


def grid_problem(grid: str, name: str = "grid") -> str:
    """Return a recycling problem: every litter item recycled, robots start at `A`."""
    cells = _cells(grid)
    open_cells = sorted(c for c, ch in cells.items() if ch != "#")
    robots = [c for c in open_cells if cells[c] == "A"]
    litter = [c for c in open_cells if cells[c] == "L"]
    bins = [c for c in open_cells if cells[c] == "B"]
    init = ["(map_loaded)"]
    for i, cell in enumerate(robots, start=1):
        init += [f"(in r{i} {_name(cell)})", f"(= (loaded_amount r{i}) 0)"]
        init.append(f"(= (detection_depth r{i}) 1)")
    init += [f"(litter_pose l{i} {_name(c)})" for i, c in enumerate(litter, start=1)]
    init += [f"(bin_pose b{i} {_name(c)})" for i, c in enumerate(bins, start=1)]
    init += [f"(free {_name(c)})" for c in open_cells if cells[c] in ".L"]
    for x, y in open_cells:
        for other in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
            if other in open_cells:
                init.append(f"(near {_name((x, y))} {_name(other)})")
    objects = [
        " ".join(f"r{i}" for i in range(1, len(robots) + 1)) + " - robot",
        " ".join(f"l{i}" for i in range(1, len(litter) + 1)) + " - plastic",
        " ".join(f"b{i}" for i in range(1, len(bins) + 1)) + " - bin",
        " ".join(_name(c) for c in open_cells) + " - cell",
    ]
    goal = " ".join(f"(recycled l{i})" for i in range(1, len(litter) + 1))
    return (
        f"(define (problem {name}) (:domain recycling)\n"
        f"  (:objects {' '.join(objects)})\n"
        f"  (:init {' '.join(init)})\n"
        f"  (:goal (and {goal})))\n"
    )


def _check_plan(planned_names: list[str], litter: int) -> None:
    assert sum(n.startswith("litter_pickup") for n in planned_names) == litter
    assert sum(n.startswith("recycle") for n in planned_names) == litter


def test_three_by_three(tmp_path: Path) -> None:
    grid = """
    B..
    A.L
    ...
    """
    planned = plan_and_validate(tmp_path, DOMAIN, grid_problem(grid.replace(" ", "")))
    names = [a.name for a in planned.plan.actions]
    _check_plan(names, 1)
    # two moves out, pickup, two moves back, recycle: 2 + 3 + 2 + 3 plus epsilons
    assert planned.plan.makespan == pytest.approx(10.0, abs=0.05)


def test_two_robots_share_the_work(tmp_path: Path) -> None:
    grid = """
    L...A
    ..B..
    A...L
    """
    planned = plan_and_validate(tmp_path, DOMAIN, grid_problem(grid.replace(" ", "")))
    names = [a.name for a in planned.plan.actions]
    _check_plan(names, 2)
    assert len(planned.plan) > 0


@pytest.mark.parametrize("map_name", ["corridor-6x3", "paper-7x7"])
def test_map_files(tmp_path: Path, map_name: str) -> None:
    grid = tomllib.loads((MAPS / f"{map_name}.toml").read_text())["grid"]
    cells = _cells(grid)
    planned = plan_and_validate(tmp_path, DOMAIN, grid_problem(grid, map_name), name=map_name)
    _check_plan([a.name for a in planned.plan.actions], sum(ch == "L" for ch in cells.values()))


# -- random grids ---------------------------------------------------------------------


def _connected(open_cells: set[Cell]) -> bool:
    if not open_cells:
        return False
    first = next(iter(open_cells))
    seen, queue = {first}, deque([first])
    while queue:
        x, y = queue.popleft()
        for other in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
            if other in open_cells and other not in seen:
                seen.add(other)
                queue.append(other)
    return seen == open_cells


@st.composite
def grids(draw: st.DrawFn) -> str:
    """Draw a 3x3..5x5 grid: one robot, one bin, 1-2 litter, walls keeping it connected.

    The bin blocks its cell, so connectivity is required of the cells other than it,
    and the bin needs a walkable neighbour.
    """
    width, height = draw(st.integers(3, 5)), draw(st.integers(3, 5))
    all_cells = [(x, y) for y in range(height) for x in range(width)]
    litter = draw(st.integers(1, 2))
    chosen = draw(st.permutations(all_cells))
    robot, bin_cell, items = chosen[0], chosen[1], chosen[2 : 2 + litter]
    rest = chosen[2 + litter :]
    walls: set[Cell] = set()
    for cell, wall in zip(rest, draw(st.lists(st.booleans(), min_size=len(rest))), strict=False):
        walkable = set(all_cells) - walls - {cell, bin_cell}
        bx, by = bin_cell
        bin_ok = any(
            n in walkable for n in ((bx + 1, by), (bx - 1, by), (bx, by + 1), (bx, by - 1))
        )
        if wall and _connected(walkable) and bin_ok:
            walls.add(cell)
    walkable = set(all_cells) - walls - {bin_cell}
    bx, by = bin_cell
    if not (
        _connected(walkable) and walkable & {(bx + 1, by), (bx - 1, by), (bx, by + 1), (bx, by - 1)}
    ):
        # only happens without walls, when the bin itself cuts the grid in two
        bin_cell, robot = robot, bin_cell
    marks = {robot: "A", bin_cell: "B", **{c: "L" for c in items}, **{c: "#" for c in walls}}
    return "\n".join("".join(marks.get((x, y), ".") for x in range(width)) for y in range(height))


@settings(
    max_examples=10,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(grid=grids())
def test_random_grids_give_valid_plans(tmp_path: Path, grid: str) -> None:
    cells = _cells(grid)
    walkable = {c for c, ch in cells.items() if ch not in "#B"}
    if not _connected(walkable):
        return  # the swap above could not fix it; nothing to plan for
    name = "g" + str(abs(hash(grid)))
    planned = plan_and_validate(tmp_path, DOMAIN, grid_problem(grid, name), name=name)
    _check_plan([a.name for a in planned.plan.actions], sum(ch == "L" for ch in cells.values()))
