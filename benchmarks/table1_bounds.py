"""Lower bounds beside Table I: the static optimum and a clairvoyant planner's best plan.

- static optimum: every litter item known, no people; `cbdi problem MAP --litter all`
  planned by `cbdi plan --anytime` (22 moves on the paper's 7x7 map);
- clairvoyant: every item known and the people's walk given to the planner as timed
  initial literals. The walk comes from the world core (`cbdi_recycling.world.World`), built
  from the run's own `cbdi up` flags (seeded phase and jitter included), with the robot
  standing still on its start cell, so people are never held up by it; in a real run a
  robot in the way makes a person wait, and actions take their domain durations here
  (no duration noise, no random failures), so this is a bound of a slightly different
  world. The planner minimises makespan, not moves, within its time limit: the figure is
  the moves of the best plan it found, labelled so, never an optimum.

A person's cell is not `free` from the epoch it steps in until the epoch it steps out:
a world move ending at t fails if a person stood on the target after epoch t-1, and the
domain's `move` needs `(over all (free ?to))` on (t-1, t), which those TILs decide alike.
"""

from __future__ import annotations

import csv
import hashlib
import json
import subprocess
import tempfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from cbdi_recycling.maps import WorldMap
from cbdi_recycling.problem import cell_name, problem_text
from cbdi_recycling.world import World
from table1_runner import CBDI, execute

from cbdi.wire.world import Cell

__all__ = [
    "HORIZON",
    "Bound",
    "clairvoyant_bounds",
    "clairvoyant_problem",
    "clairvoyant_problems",
    "launcher_world",
    "people_timeline",
    "read_bounds",
    "static_optimum",
    "write_bounds",
]

ROOT = Path(__file__).resolve().parents[1]
DOMAIN = ROOT / "domains/recycling/pddl/domain.pddl"
HORIZON = 80  # epochs of people's walk given as TILs (the static optimum takes 34)

Change = tuple[int, str, Cell]  # (epoch, person, cell it stands on from then)


@dataclass(frozen=True)
class Bound:
    """A bound's moves and makespan; `status` is the planner's (solved, timeout, ...)."""

    kind: str  # "static" or "clairvoyant"
    move_step: int | None
    seed: int | None
    moves: int | None
    makespan: float | None
    status: str
    horizon: int = 0
    timeout: float = 0.0
    note: str = ""


def launcher_world(up_argv: Sequence[str]) -> World:
    """Build the world `cbdi up UP_ARGV` would start, through the launcher's own parsing.

    The launcher's parser and scenario overrides, its world command line, then the world
    service's settings reader and builder: every option, passed through or the
    scenario's own (people's phase and jitter), reaches this world as it reaches the
    real one. Those are private helpers of `cbdi.launcher`; a test keeps this in step.
    """
    from cbdi.launcher import cli, specs
    from cbdi.runtime import load_config
    from cbdi_world.service import WorldSettings, build_world

    scenario = cli.scenario_from_args(cli._parser().parse_args(list(up_argv)))
    spec = next(s for s in specs.run_specs(scenario, "tcp/127.0.0.1:0") if s.service == "world")
    argv = list(spec.argv)
    settings = load_config(
        WorldSettings, argv[argv.index("--map") :], prog="cbdi-world", section="world", env={}
    )
    world = build_world(settings)
    assert isinstance(world, World)  # the recycling grid (its scenarios name it)
    return world


def people_timeline(world: World, horizon: int) -> tuple[Change, ...]:
    """Return where each person stands at epoch 0 and every step up to `horizon`.

    The world is stepped with its robot never asked to act: it stands on its start cell.
    """
    changes: list[Change] = [(0, p.name, p.cell) for p in world.people]
    where = {p.name: p.cell for p in world.people}
    for _ in range(horizon):
        world.step()
        for p in world.people:
            if p.cell != where[p.name]:
                changes.append((world.epoch, p.name, p.cell))
                where[p.name] = p.cell
    return tuple(changes)


def clairvoyant_problem(world_map: WorldMap, timeline: Sequence[Change]) -> str:
    """Return the map's problem (all litter) with people's cells as timed literals.

    People's cells at epoch 0 (wherever the seed put them on their loops) start
    not free; each step frees the cell left and takes the cell entered.
    """
    text = problem_text(world_map, litter="all", name=f"{world_map.name}-clairvoyant")
    where: dict[str, Cell] = {}
    tils: list[str] = []
    for epoch, person, cell in timeline:
        if epoch == 0:
            fact = f"\n    (free {cell_name(cell)})"
            if fact not in text:
                raise ValueError(f"{person} starts on {list(cell)}, which is not free")
            text = text.replace(fact, "", 1)
        else:
            tils.append(f"(at {epoch} (free {cell_name(where[person])}))")
            tils.append(f"(at {epoch} (not (free {cell_name(cell)})))")
        where[person] = cell
    head = "  (:init\n    "
    return text.replace(head, head + "\n    ".join(tils) + "\n    ", 1) if tils else text


# The search is bounded by node expansions, so a bound is the same on any machine; the
# timeout only guards against a runaway search (its status then says `timeout`).
BOUND_EXPANSIONS = 20000


def plan_moves(problem: Path, timeout: float) -> tuple[int | None, float | None, str]:
    """Plan a problem anytime; return the best plan's moves, makespan and the status."""
    argv = [CBDI, "plan", str(DOMAIN), str(problem), "--anytime", "--json"]
    argv += ["--expansions", str(BOUND_EXPANSIONS), "--timeout", f"{max(timeout, 300):g}"]
    code, out, _, _ = execute(argv, timeout + 60)
    try:
        report: dict[str, Any] = json.loads(out)
    except json.JSONDecodeError:
        return None, None, "killed" if code == -9 else f"error (exit {code})"
    plan = report.get("plan") or []
    if not plan:
        return None, None, str(report.get("status", f"exit {code}"))
    moves = sum(1 for step in plan if str(step["action"]).split()[0] == "move")
    return moves, float(report.get("makespan", 0.0)), str(report.get("status", "solved"))


def static_optimum(map_path: Path, timeout: float) -> Bound:
    """Plan the map with all litter known and no people (`cbdi problem --litter all`)."""
    with tempfile.TemporaryDirectory() as folder:
        problem = Path(folder) / "static.pddl"
        argv = [CBDI, "problem", str(map_path), "--litter", "all", "-o", str(problem)]
        done = subprocess.run(argv, capture_output=True, text=True, timeout=60)
        if done.returncode != 0:
            note = done.stderr.strip()[-200:]
            return Bound("static", None, None, None, None, "error", timeout=timeout, note=note)
        moves, makespan, status = plan_moves(problem, timeout)
    return Bound("static", None, None, moves, makespan, status, timeout=timeout)


def clairvoyant_problems(
    cases: Mapping[tuple[int, int], Sequence[str]], horizon: int = HORIZON
) -> dict[tuple[int, int], str]:
    """Return the clairvoyant problem of each (move_step, seed), from its `cbdi up` flags."""
    texts: dict[tuple[int, int], str] = {}
    for case, up_argv in sorted(cases.items()):
        world = launcher_world(up_argv)
        texts[case] = clairvoyant_problem(world.map, people_timeline(world, horizon))
    return texts


def clairvoyant_bounds(
    texts: dict[tuple[int, int], str],
    *,
    timeout: float,
    jobs: int,
    horizon: int = HORIZON,
    step: Callable[[str], None] | None = None,
) -> list[Bound]:
    """Plan each case's problem; identical problems (same people's walk) are planned once."""
    unique = sorted(set(texts.values()), key=_digest)
    with tempfile.TemporaryDirectory() as folder, ThreadPoolExecutor(max_workers=jobs) as pool:
        paths = {t: Path(folder) / f"{_digest(t)}.pddl" for t in unique}
        for text, path in paths.items():
            path.write_text(text, encoding="utf-8")
        futures = {t: pool.submit(_plan_one, paths[t], timeout, step) for t in unique}
        found = {t: f.result() for t, f in futures.items()}
    out = []
    for (move_step, seed), text in sorted(texts.items()):
        moves, makespan, status = found[text]
        note = "plan outlasts the horizon" if makespan is not None and makespan > horizon else ""
        out.append(
            Bound("clairvoyant", move_step, seed, moves, makespan, status, horizon, timeout, note)
        )
    return out


def _plan_one(
    path: Path, timeout: float, step: Callable[[str], None] | None
) -> tuple[int | None, float | None, str]:
    found = plan_moves(path, timeout)
    if step is not None:
        step(f"clairvoyant {path.stem[:8]}: {found[2]} {found[0]} moves")
    return found


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:16]


_BOUND_FIELDS = tuple(f.name for f in fields(Bound))


def write_bounds(bounds: Iterable[Bound], path: Path) -> None:
    """Write the bounds as CSV, sorted (static first, then by pace and seed)."""
    ordered = sorted(bounds, key=_bound_key)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as out:
        writer = csv.DictWriter(out, fieldnames=_BOUND_FIELDS, lineterminator="\n")
        writer.writeheader()
        writer.writerows({k: _text(getattr(b, k)) for k in _BOUND_FIELDS} for b in ordered)


def _text(value: object) -> str:
    if value is None:
        return ""
    return repr(round(value, 6)) if isinstance(value, float) else str(value)


def read_bounds(path: Path) -> list[Bound]:
    """Read the bounds a table wrote; raise KeyError/ValueError on another file."""
    out = []
    with path.open(newline="", encoding="utf-8") as handle:
        for r in csv.DictReader(handle):
            out.append(
                Bound(
                    kind=r["kind"],
                    move_step=int(r["move_step"]) if r["move_step"] else None,
                    seed=int(r["seed"]) if r["seed"] else None,
                    moves=int(r["moves"]) if r["moves"] else None,
                    makespan=float(r["makespan"]) if r["makespan"] else None,
                    status=r["status"],
                    horizon=int(r["horizon"] or 0),
                    timeout=float(r["timeout"] or 0),
                    note=r["note"],
                )
            )
    return sorted(out, key=_bound_key)


def _bound_key(b: Bound) -> tuple[int, int, int]:
    return (0 if b.kind == "static" else 1, b.move_step or 0, b.seed or 0)
