"""Map files: the grid, bins, litter, people and agents' start cells of a recycling world.

A map is a TOML file (format in docs/maps.md). The `grid` draws the static layout, one
row per line from y=0 at the top, one character per cell from x=0 at the left:

    .  free          #  wall        B  bin
    A  agent start (in reading order)
    L  litter known to agents at start        l  litter to be discovered by sensing

People walk closed loops given as `[[people]]` tables. Every problem is a `MapError`
naming the file, the field (`grid row 3 column 5`, `people[1].path[4]`) and the reason.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from cbdi.wire.world import Cell
from cbdi_recycling.errors import MapError

__all__ = [
    "DEFAULT_DURATIONS",
    "PersonSpec",
    "WorldMap",
    "load_map",
    "parse_map",
    "with_situation",
]

DEFAULT_DURATIONS = {"move": 1.0, "pickup": 3.0, "recycle": 3.0}
_LEGEND = {".", "#", "B", "A", "L", "l"}


@dataclass(frozen=True)
class PersonSpec:
    """A person walking a closed loop: starts at `path[0]`, steps every `move_step` epochs.

    A person whose next cell stays taken for `patience` epochs (a robot standing there,
    itself waiting for the person) turns round and walks the loop the other way, as
    people do; 0: waits for ever.
    """

    name: str
    path: tuple[Cell, ...]
    move_step: int
    patience: int = 12


@dataclass(frozen=True)
class WorldMap:
    """A validated map."""

    name: str
    source: str
    width: int
    height: int
    walls: frozenset[Cell]
    bins: dict[str, Cell]
    agent_starts: tuple[Cell, ...]
    litter: dict[str, tuple[Cell, bool]]
    people: tuple[PersonSpec, ...] = ()
    spawn_probability: float = 0.0
    epoch_duration: float = 1.0
    durations: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_DURATIONS))
    detection_depth: int = 1
    capacity: int = 3
    description: str = ""

    def inside(self, cell: Cell) -> bool:
        return 0 <= cell[0] < self.width and 0 <= cell[1] < self.height


def load_map(path: str | Path) -> WorldMap:
    """Read and validate a map file."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MapError(str(p), "file", "not found") from None
    except OSError as exc:
        raise MapError(str(p), "file", str(exc)) from None
    except UnicodeDecodeError as exc:
        raise MapError(str(p), "file", f"not UTF-8 text (byte {exc.start})") from None
    return parse_map(text, str(p))


def parse_map(text: str, source: str = "<map>") -> WorldMap:
    """Validate map `text`; `source` names it in errors."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MapError(source, "toml", str(exc)) from None
    m = _Reader(source, data)
    width, height, cells = m.grid()
    walls = frozenset(c for c, ch in cells.items() if ch == "#")
    bins = {
        f"bin_{x}_{y}": (x, y) for (x, y), ch in sorted(cells.items(), key=_reading) if ch == "B"
    }
    starts = tuple(c for c, ch in sorted(cells.items(), key=_reading) if ch == "A")
    litter = {
        f"plastic_{x}_{y}": ((x, y), ch == "L")
        for (x, y), ch in sorted(cells.items(), key=_reading)
        if ch in "Ll"
    }
    if not starts:
        raise MapError(source, "grid", "no agent start cell (A)")
    if not bins:
        raise MapError(source, "grid", "no bin (B)")
    blocked = walls | set(bins.values())
    people = tuple(m.person(i, raw, width, height, blocked) for i, raw in enumerate(m.people()))
    m.check_people_apart(people, starts)
    agents = m.table("agents")
    return WorldMap(
        name=m.string("name", data, "name"),
        source=source,
        width=width,
        height=height,
        walls=walls,
        bins=bins,
        agent_starts=starts,
        litter=litter,
        people=people,
        spawn_probability=m.probability(),
        epoch_duration=m.positive(data, "epoch_duration", 1.0),
        durations=m.durations(),
        detection_depth=m.natural(agents, "agents.detection_depth", 1),
        capacity=max(1, m.natural(agents, "agents.capacity", 3)),
        description=str(data.get("description", "")),
    )


def _reading(item: tuple[Cell, str]) -> tuple[int, int]:
    (x, y), _ = item
    return (y, x)


class _Reader:
    """Typed access to the raw TOML with errors that name the field."""

    def __init__(self, source: str, data: dict[str, Any]) -> None:
        self.source = source
        self.data = data

    def fail(self, field_name: str, reason: str) -> MapError:
        return MapError(self.source, field_name, reason)

    def string(self, key: str, table: dict[str, Any], name: str) -> str:
        value = table.get(key)
        if not isinstance(value, str) or not value:
            raise self.fail(name, "missing or not a non-empty string")
        return value

    def table(self, key: str) -> dict[str, Any]:
        value = self.data.get(key, {})
        if not isinstance(value, dict):
            raise self.fail(key, "expected a table")
        return value

    def natural(self, table: dict[str, Any], name: str, default: int) -> int:
        value = table.get(name.split(".")[-1], default)
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            raise self.fail(name, f"expected an integer >= 0, got {value!r}")
        return value

    def positive(self, table: dict[str, Any], name: str, default: float) -> float:
        value = table.get(name.split(".")[-1], default)
        finite = isinstance(value, int | float) and math.isfinite(value)
        if isinstance(value, bool) or not finite or value <= 0:
            raise self.fail(name, f"expected a finite number > 0, got {value!r}")
        return float(value)

    def probability(self) -> float:
        value = self.table("litter").get("spawn_probability", 0.0)
        if isinstance(value, bool) or not isinstance(value, int | float) or not 0 <= value <= 1:
            raise self.fail("litter.spawn_probability", f"expected 0..1, got {value!r}")
        return float(value)

    def durations(self) -> dict[str, float]:
        table = self.table("durations")
        unknown = set(table) - set(DEFAULT_DURATIONS)
        if unknown:
            raise self.fail("durations", f"unknown actions {sorted(unknown)}")
        return {a: self.positive(table, f"durations.{a}", d) for a, d in DEFAULT_DURATIONS.items()}

    def grid(self) -> tuple[int, int, dict[Cell, str]]:
        raw = self.data.get("grid")
        if not isinstance(raw, str):
            raise self.fail("grid", "missing or not a string")
        rows = [line.strip() for line in raw.strip("\n").splitlines() if line.strip()]
        if not rows:
            raise self.fail("grid", "empty")
        width = len(rows[0])
        cells: dict[Cell, str] = {}
        for y, row in enumerate(rows):
            if len(row) != width:
                raise self.fail(f"grid row {y}", f"has {len(row)} cells, row 0 has {width}")
            for x, ch in enumerate(row):
                if ch not in _LEGEND:
                    raise self.fail(
                        f"grid row {y} column {x}", f"unknown cell {ch!r} (use . # B A L l)"
                    )
                cells[(x, y)] = ch
        return width, len(rows), cells

    def people(self) -> list[Any]:
        value = self.data.get("people", [])
        if not isinstance(value, list):
            raise self.fail("people", "expected an array of tables ([[people]])")
        return value

    def person(
        self, i: int, raw: Any, width: int, height: int, blocked: frozenset[Cell] | set[Cell]
    ) -> PersonSpec:
        where = f"people[{i}]"
        if not isinstance(raw, dict):
            raise self.fail(where, "expected a table")
        name = raw.get("name", f"person{i + 1}")
        step = raw.get("move_step")
        if not isinstance(step, int) or isinstance(step, bool) or step < 1:
            raise self.fail(f"{where}.move_step", f"expected an integer >= 1, got {step!r}")
        path_raw = raw.get("path")
        if not isinstance(path_raw, list) or not path_raw:
            raise self.fail(f"{where}.path", "expected a non-empty list of [x, y]")
        path: list[Cell] = []
        for j, c in enumerate(path_raw):
            here = f"{where}.path[{j}]"
            if (
                not isinstance(c, list)
                or len(c) != 2
                or not all(isinstance(v, int) and not isinstance(v, bool) for v in c)
            ):
                raise self.fail(here, f"expected [x, y], got {c!r}")
            cell = (c[0], c[1])
            if not (0 <= cell[0] < width and 0 <= cell[1] < height):
                raise self.fail(here, f"{list(cell)} is outside the {width}x{height} map")
            if cell in blocked:
                raise self.fail(here, f"{list(cell)} is a wall or a bin")
            if path and not _adjacent(path[-1], cell):
                raise self.fail(here, f"{list(cell)} is not next to {list(path[-1])}")
            path.append(cell)
        if len(path) > 1 and not _adjacent(path[-1], path[0]):
            raise self.fail(
                f"{where}.path", "the loop is not closed: the last cell must be next to the first"
            )
        patience = raw.get("patience", 12)
        if not isinstance(patience, int) or isinstance(patience, bool) or patience < 0:
            raise self.fail(f"{where}.patience", f"expected an integer >= 0, got {patience!r}")
        return PersonSpec(name=str(name), path=tuple(path), move_step=step, patience=patience)

    def check_people_apart(self, people: tuple[PersonSpec, ...], starts: tuple[Cell, ...]) -> None:
        seen: dict[Cell, str] = {}
        for i, p in enumerate(people):
            start = p.path[0]
            if start in starts:
                raise self.fail(f"people[{i}].path[0]", "starts on an agent start cell")
            if start in seen:
                raise self.fail(f"people[{i}].path[0]", f"starts where {seen[start]} starts")
            seen[start] = p.name
        if len({p.name for p in people}) != len(people):
            raise self.fail("people", "names must be unique")


def _adjacent(a: Cell, b: Cell) -> bool:
    return abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1


def with_situation(
    world_map: WorldMap,
    *,
    move_step: int = 0,
    detection_depth: int = -1,
    known_litter: int = -1,
    spawn_probability: float = -1.0,
) -> WorldMap:
    """Return the map set up for one of the paper's situations (0 / -1: keep the map's).

    `move_step` for every person, the agents' `detection_depth`, how many litter items
    (the first ones in reading order) agents know at the start, and the probability of
    new litter appearing per epoch.
    """
    if spawn_probability > 1.0:
        raise MapError(
            world_map.source, "spawn_probability", f"must be in [0, 1], got {spawn_probability}"
        )
    if move_step < 0:
        raise MapError(world_map.source, "move_step", f"must be >= 1, got {move_step}")
    people = world_map.people
    if move_step:
        people = tuple(replace(p, move_step=move_step) for p in people)
    depth = world_map.detection_depth if detection_depth < 0 else detection_depth
    litter = world_map.litter
    if known_litter >= 0:
        if known_litter > len(litter):
            raise MapError(
                world_map.source,
                "known_litter",
                f"{known_litter} known items but the map has {len(litter)}",
            )
        order = sorted(litter, key=lambda n: (litter[n][0][1], litter[n][0][0]))
        litter = {n: (litter[n][0], i < known_litter) for i, n in enumerate(order)}
    spawn = world_map.spawn_probability if spawn_probability < 0 else spawn_probability
    return replace(
        world_map, people=people, detection_depth=depth, litter=litter, spawn_probability=spawn
    )
