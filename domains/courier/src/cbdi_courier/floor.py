"""An office floor of the courier domain, read from a map file (TOML).

    name = "office-9x5"
    epoch_duration = 1.0       # simulated seconds per epoch
    sensing = 1                # a robot senses the cells up to this far (square)
    battery = 12               # every robot's capacity; robots start charged
    door_close_probability = 0.05   # per epoch, per open door nobody stands in (seeded)
    layout = [                 # '#' wall, '.' floor, 'C' dock, 'D' door, '1'-'9' robots
      "#########",
      "#1.D...C#",
      "#########",
    ]

    [[parcels]]
    name = "p1"
    at = [6, 1]                # x (column), y (row)
    to = [1, 1]
    rounds = 1                 # deliveries asked (default 1); more: the parcel comes back
    again_after = 5.0          # seconds after a delivery it waits at `at` again (rounds > 1)

    [[carts]]                  # a dynamic obstacle: rolls along its route and back
    name = "cart1"
    route = [[4, 1], [5, 1], [6, 1]]
    step = 2                   # epochs per cell

Every problem is a `ConfigError` naming the file and the field.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cbdi.errors import ConfigError
from cbdi.wire.world import MapLayer, MapLink, MapPlace, MapView

__all__ = ["Cart", "Floor", "Parcel", "cell_name", "load_floor"]

Cell = tuple[int, int]


def cell_name(c: Cell) -> str:
    return f"c_{c[0]}_{c[1]}"


@dataclass(frozen=True)
class Parcel:
    """A parcel to carry from `at` to `to`, `rounds` times: after each delivery but the
    last it waits at `at` again `again_after` seconds later (work that comes back)."""

    name: str
    at: Cell
    to: Cell
    rounds: int = 1
    again_after: float = 0.0


@dataclass(frozen=True)
class Cart:
    name: str
    route: tuple[Cell, ...]
    step: int


@dataclass(frozen=True)
class Floor:
    name: str
    width: int
    height: int
    walls: frozenset[Cell]
    doors: frozenset[Cell]
    docks: frozenset[Cell]
    starts: tuple[Cell, ...]
    parcels: tuple[Parcel, ...]
    carts: tuple[Cart, ...]
    epoch_duration: float
    sensing: int
    battery: int
    door_close_probability: float

    def floor_cell(self, c: Cell) -> bool:
        return 0 <= c[0] < self.width and 0 <= c[1] < self.height and c not in self.walls

    def view(self) -> MapView:
        """How the views draw the floor: walls (`#`) and docks (`D`), and the graph the
        PDDL map is, every floor cell a place (`c_X_Y` at its centre, drawn as floor in
        text) linked to its floor neighbours (the `link` facts, each pair once)."""
        walls = MapLayer(name="walls", cells=sorted(self.walls))
        docks = MapLayer(
            name="docks", cells=sorted(self.docks), glyph="D", colour=(60, 90, 200), size=0.8
        )
        cells = [(x, y) for y in range(self.height) for x in range(self.width)]
        cells = [c for c in cells if self.floor_cell(c)]
        places = [
            MapPlace(name=cell_name(c), at=(c[0] + 0.5, c[1] + 0.5), glyph=".") for c in cells
        ]
        links = [
            MapLink(a=cell_name(c), b=cell_name(n)) for c in cells for n in self.links(c) if c < n
        ]
        return MapView(
            width=self.width, height=self.height, layers=[walls, docks], places=places, links=links
        )

    def links(self, c: Cell) -> list[Cell]:
        x, y = c
        return [n for n in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)) if self.floor_cell(n)]


def _number(
    data: dict[str, Any],
    key: str,
    where: str,
    low: float,
    high: float,
    default: float | None = None,
    field: str = "",
) -> float:
    """Read number `key` of table `field` (top level: ""); absent: `default` if given."""
    value = data.get(key, default)
    name = f"{field}.{key}" if field else key
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(where, name, f"expected a number, got {value!r}")
    if not (math.isfinite(value) and low <= value <= high):
        raise ConfigError(where, name, f"expected a number in [{low:g}, {high:g}], got {value!r}")
    return float(value)


def _cell(value: Any, where: str, field: str, floor_ok: Any) -> Cell:
    if (
        not isinstance(value, list)
        or len(value) != 2
        or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)
    ):
        raise ConfigError(where, field, f"expected a cell [x, y], got {value!r}")
    cell = (value[0], value[1])
    if not floor_ok(cell):
        raise ConfigError(where, field, f"{list(cell)} is not a floor cell of the layout")
    return cell


def load_floor(path: str | Path) -> Floor:
    """Read and check a courier map file."""
    where = str(path)
    data = _read_toml(path, where)
    rows = data.get("layout")
    if not isinstance(rows, list) or not rows or not all(isinstance(r, str) and r for r in rows):
        raise ConfigError(where, "layout", "expected a list of non-empty strings")
    width, height = len(rows[0]), len(rows)
    if any(len(r) != width for r in rows):
        raise ConfigError(where, "layout", "every row must be as long as the first")
    walls, doors, docks, starts = _layout(rows, where)

    def ok(c: Cell) -> bool:
        return 0 <= c[0] < width and 0 <= c[1] < height and c not in walls

    return Floor(
        name=str(data.get("name", Path(path).stem)),
        width=width,
        height=height,
        walls=frozenset(walls),
        doors=frozenset(doors),
        docks=frozenset(docks),
        starts=tuple(starts[k] for k in sorted(starts)),
        parcels=_parcels(data, where, ok),
        carts=_carts(data, where, ok),
        epoch_duration=_number(data, "epoch_duration", where, 1e-3, 1e6),
        sensing=int(_number(data, "sensing", where, 0, 1000)),
        battery=int(_number(data, "battery", where, 1, 1e6)),
        door_close_probability=_number(data, "door_close_probability", where, 0, 1),
    )


def _read_toml(path: str | Path, where: str) -> dict[str, Any]:
    try:
        return tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(where, "file", exc.strerror or str(exc)) from None
    except UnicodeDecodeError as exc:
        raise ConfigError(where, "file", f"not UTF-8 text (byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(where, "toml", str(exc)) from None


def _layout(rows: list[str], where: str) -> tuple[set[Cell], set[Cell], set[Cell], dict[str, Cell]]:
    """The layout's walls, doors, docks and robot starts (by digit)."""
    walls: set[Cell] = set()
    doors: set[Cell] = set()
    docks: set[Cell] = set()
    starts: dict[str, Cell] = {}
    for y, row in enumerate(rows):
        for x, ch in enumerate(row):
            if ch == "#":
                walls.add((x, y))
            elif ch == "D":
                doors.add((x, y))
            elif ch == "C":
                docks.add((x, y))
            elif ch.isdigit() and ch != "0":
                if ch in starts:
                    raise ConfigError(where, "layout", f"robot start {ch} appears twice")
                starts[ch] = (x, y)
            elif ch != ".":
                raise ConfigError(where, "layout", f"row {y}, column {x}: unknown cell {ch!r}")
    return walls, doors, docks, starts


def _named_tables(
    data: dict[str, Any], key: str, where: str
) -> list[tuple[str, str, dict[str, Any]]]:
    """The tables of list `key`, each with its field path and its checked name."""
    raw_list = data.get(key, [])
    if not isinstance(raw_list, list):
        raise ConfigError(where, key, "expected a list of tables")
    out = []
    for i, raw in enumerate(raw_list):
        field = f"{key}[{i}]"
        if not isinstance(raw, dict):
            raise ConfigError(where, field, "expected a table")
        name = raw.get("name")
        if not isinstance(name, str) or not name.isidentifier():
            raise ConfigError(where, f"{field}.name", f"expected a name, got {name!r}")
        out.append((field, name, raw))
    return out


def _parcels(data: dict[str, Any], where: str, ok: Callable[[Cell], bool]) -> tuple[Parcel, ...]:
    parcels: list[Parcel] = []
    for field, name, raw in _named_tables(data, "parcels", where):
        rounds = _number(raw, "rounds", where, 1, 1e6, default=1, field=field)
        if rounds != int(rounds):
            raise ConfigError(where, f"{field}.rounds", f"expected a whole number, got {rounds}")
        again = _number(raw, "again_after", where, 0, 1e6, default=0.0, field=field)
        parcels.append(
            Parcel(name, _cell(raw.get("at"), where, f"{field}.at", ok),
                   _cell(raw.get("to"), where, f"{field}.to", ok), int(rounds), again)
        )  # fmt: skip
    if len({p.name for p in parcels}) != len(parcels):
        raise ConfigError(where, "parcels", "parcel names must be unique")
    return tuple(parcels)


def _carts(data: dict[str, Any], where: str, ok: Callable[[Cell], bool]) -> tuple[Cart, ...]:
    carts: list[Cart] = []
    for field, name, raw in _named_tables(data, "carts", where):
        route = raw.get("route")
        if not isinstance(route, list) or not route:
            raise ConfigError(where, f"{field}.route", "expected a list of cells")
        cells = tuple(_cell(c, where, f"{field}.route", ok) for c in route)
        for a, b in itertools.pairwise(cells):
            if abs(a[0] - b[0]) + abs(a[1] - b[1]) != 1:
                raise ConfigError(where, f"{field}.route", f"{list(a)} to {list(b)} is no step")
        step = int(_number(raw, "step", where, 1, 1e6, field=field))
        carts.append(Cart(name, cells, step))
    return tuple(carts)
