"""`cbdi map`: seeded random recycling maps (and a BDI scenario to run each).

A generated map is a function of its seed and recipe: random walls that keep every free
cell connected, bins, litter, agents' start cells and people walking there-and-back
loops. With `bottleneck` (the default) each bin has a single free neighbour, the only
cell a robot can recycle from (itself with two ways in, never a dead end), and the first
person's loop crosses it: robots must wait for people to pass and must not block each
other there.

    cbdi map --seed 7 -o runs/gen-7.toml --scenario runs/gen-7-bdi.toml --agents 2
    cbdi up runs/gen-7-bdi.toml
"""

from __future__ import annotations

import argparse
import random
import sys
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from cbdi.wire.world import Cell
from cbdi_recycling.errors import GridError
from cbdi_recycling.maps import parse_map

__all__ = ["Recipe", "generate_map", "main", "scenario_text"]


@dataclass(frozen=True)
class Recipe:
    """What a generated map holds."""

    width: int = 9
    height: int = 9
    wall_fraction: float = 0.15
    bins: int = 1
    litter: int = 4
    known_litter: int = -1  # -1: all known at the start
    people: int = 2
    agents: int = 1
    move_step: int = 4
    bottleneck: bool = True

    def check(self) -> None:
        if not (3 <= self.width <= 64 and 3 <= self.height <= 64):
            raise ValueError(f"size {self.width}x{self.height}: expected 3..64 per side")
        if not 0.0 <= self.wall_fraction <= 0.5:
            raise ValueError(f"wall fraction {self.wall_fraction}: expected 0..0.5")
        for name in ("bins", "agents", "move_step"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}: expected at least 1")
        if self.litter < 0 or self.people < 0:
            raise ValueError("litter and people: expected at least 0")


def _neighbours(c: Cell, w: int, h: int) -> list[Cell]:
    x, y = c
    out = [(x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)]
    return [n for n in out if 0 <= n[0] < w and 0 <= n[1] < h]


def _connected(free: set[Cell], w: int, h: int) -> bool:
    if not free:
        return False
    start = min(free)
    seen, todo = {start}, deque([start])
    while todo:
        for n in _neighbours(todo.popleft(), w, h):
            if n in free and n not in seen:
                seen.add(n)
                todo.append(n)
    return len(seen) == len(free)


def _path(free: set[Cell], a: Cell, b: Cell, w: int, h: int) -> list[Cell]:
    back: dict[Cell, Cell | None] = {a: None}
    todo = deque([a])
    while todo:
        c = todo.popleft()
        if c == b:
            break
        for n in _neighbours(c, w, h):
            if n in free and n not in back:
                back[n] = c
                todo.append(n)
    out: list[Cell] = []
    cur: Cell | None = b
    while cur is not None:
        out.append(cur)
        cur = back[cur]
    return out[::-1]


class _Layout:
    def __init__(self, seed: int, r: Recipe) -> None:
        self.rng = random.Random(seed)
        self.r = r
        self.w, self.h = r.width, r.height
        self.walls: set[Cell] = set()
        self.bins: list[Cell] = []
        self.access: list[Cell] = []

    def free(self) -> set[Cell]:
        taken = self.walls | set(self.bins)
        return {(x, y) for y in range(self.h) for x in range(self.w) if (x, y) not in taken}

    def place_bins(self) -> None:
        border = [
            (x, y)
            for y in range(self.h)
            for x in range(self.w)
            if x in (0, self.w - 1) or y in (0, self.h - 1)
        ]
        self.rng.shuffle(border)
        for c in border:
            if len(self.bins) == self.r.bins:
                return
            near = _neighbours(c, self.w, self.h)
            if any(n in self.bins or n in self.access or n in self.walls for n in near):
                continue
            if c in self.access:
                continue
            # The access cell has two ways in besides the bin: a robot never waits in a
            # dead end that a person walks into.
            inner = [n for n in near if len(_neighbours(n, self.w, self.h)) >= 3]
            if not inner:
                continue
            trial_walls = set(self.walls)
            access = self.rng.choice(inner)
            if self.r.bottleneck:
                trial_walls |= {n for n in near if n != access}
            before = self.walls
            self.walls = trial_walls
            self.bins.append(c)
            if _connected(self.free(), self.w, self.h):
                self.access.append(access)
                continue
            self.walls = before
            self.bins.pop()
        raise GridError(f"could not place {self.r.bins} bins on a {self.w}x{self.h} map")

    def place_walls(self) -> None:
        target = round(self.r.wall_fraction * self.w * self.h)
        keep = set(self.access)
        for a in self.access:
            keep.update(_neighbours(a, self.w, self.h))
        cells = sorted(self.free() - keep)
        self.rng.shuffle(cells)
        for c in cells:
            if len(self.walls) >= target:
                return
            self.walls.add(c)
            if not _connected(self.free(), self.w, self.h):
                self.walls.discard(c)

    def loops(self) -> list[list[Cell]]:
        free = self.free()
        out: list[list[Cell]] = []
        starts: set[Cell] = set()
        for i in range(self.r.people):
            if i == 0 and self.access:
                a = self.access[0]
                far = [c for c in sorted(free) if c != a and c not in starts]
                self.rng.shuffle(far)
                walk = next(
                    (p for c in far if 3 <= len(p := _path(free, c, a, self.w, self.h)) <= 7),
                    _path(free, far[0], a, self.w, self.h) if far else [a],
                )
            else:
                walk = self._random_walk(free, starts)
            loop = walk + walk[-2:0:-1]  # there and back: a closed loop
            starts.add(loop[0])
            out.append(loop)
        return out

    def _random_walk(self, free: set[Cell], starts: set[Cell]) -> list[Cell]:
        options = sorted(free - starts)
        walk = [self.rng.choice(options)]
        for _ in range(self.rng.randint(3, 7)):
            nxt = [n for n in _neighbours(walk[-1], self.w, self.h) if n in free and n not in walk]
            if not nxt:
                break
            walk.append(self.rng.choice(sorted(nxt)))
        return walk


def generate_map(seed: int, recipe: Recipe | None = None) -> str:
    """Return the TOML text of the map of `seed` (docs/maps.md), checked by the parser."""
    r = recipe or Recipe()
    r.check()
    lay = _Layout(seed, r)
    lay.place_bins()
    lay.place_walls()
    loops = lay.loops()
    on_loops = {c for loop in loops for c in loop}
    free = sorted(lay.free() - set(lay.access))
    lay.rng.shuffle(free)
    starts = [c for c in free if c not in on_loops][: r.agents]
    if len(starts) < r.agents:
        raise GridError(f"seed {seed}: no room for {r.agents} agents off the people's loops")
    rest = [c for c in free if c not in starts and c not in {loop[0] for loop in loops}]
    if len(rest) < r.litter:
        raise GridError(f"seed {seed}: no room for {r.litter} litter items ({len(rest)} cells)")
    litter = rest[: r.litter]
    known = r.litter if r.known_litter < 0 else r.known_litter
    rows = []
    order = {c: i for i, c in enumerate(sorted(litter, key=lambda c: (c[1], c[0])))}
    for y in range(r.height):
        row = ""
        for x in range(r.width):
            c = (x, y)
            if c in lay.walls:
                row += "#"
            elif c in lay.bins:
                row += "B"
            elif c in starts:
                row += "A"
            elif c in order:
                row += "L" if order[c] < known else "l"
            else:
                row += "."
        rows.append(row)
    people = "".join(
        f'\n[[people]]\nname = "person{i + 1}"\nmove_step = {r.move_step}\n'
        f"path = [{', '.join(f'[{x}, {y}]' for x, y in loop)}]\n"
        for i, loop in enumerate(loops)
    )
    text = (
        f'name = "generated-{seed}"\n'
        f'description = """\nA generated {r.width}x{r.height} map (cbdi map --seed {seed}): '
        f"{len(lay.walls)} walls, {r.bins} bin(s)"
        f"{' each reachable from one cell' if r.bottleneck else ''}, {len(litter)} litter "
        f'items, {len(loops)} people.\n"""\n'
        "epoch_duration = 1.0\n\n"
        f'grid = """\n{chr(10).join(rows)}\n"""\n\n'
        "[durations]\nmove = 1\npickup = 3\nrecycle = 3\n\n"
        "[agents]\ndetection_depth = 1\ncapacity = 3\n\n"
        "[litter]\nspawn_probability = 0.0\n" + people
    )
    parse_map(text, f"generated map (seed {seed})")  # what we write, the world reads
    return text


def scenario_text(map_path: Path, scenario_path: Path, agents: int, agent_file: Path) -> str:
    """Return a lockstep BDI scenario running `agents` robots on the map at `map_path`."""
    base = scenario_path.resolve().parent
    rel = Path(map_path).resolve()
    agent = agent_file.resolve()
    entries = "".join(
        f'\n[[agents]]\nname = "robot{i + 1}"\nkind = "bdi"\nagent_file = "{agent}"\n'
        for i in range(agents)
    )
    return (
        f'name = "{rel.stem}-bdi"\n'
        f'map = "{rel if not rel.is_relative_to(base) else rel.relative_to(base)}"\n\n'
        '[run]\nsimulator = "recycling"\nspeed = 10.0\nseed = 1\nuntil = "done"\n'
        "max_time = 600.0\nlockstep = true\n[world]\npeople_phase = true\n" + entries
    )


def _default_agent_file() -> Path:
    from cbdi.launcher.scenario import find_scenario

    return find_scenario("paper-7x7").parent.parent / "agents" / "recycler.toml"


def _size(text: str) -> tuple[int, int]:
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.isdigit() for p in parts):
        raise ValueError(f"size {text!r}: expected WIDTHxHEIGHT, for example 9x9")
    return int(parts[0]), int(parts[1])


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="cbdi map",
        description="Write a seeded random recycling map (and a BDI scenario to run it).",
    )
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--size", default="9x9", help="WIDTHxHEIGHT (default 9x9)")
    p.add_argument("--walls", type=float, default=0.15, help="fraction of wall cells")
    p.add_argument("--bins", type=int, default=1)
    p.add_argument("--litter", type=int, default=4)
    p.add_argument("--people", type=int, default=2)
    p.add_argument("--agents", type=int, default=1, help="start cells (and scenario robots)")
    p.add_argument("--move-step", type=int, default=4, help="people step every N epochs")
    p.add_argument(
        "--bottleneck",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="each bin reachable from one cell, crossed by a person (default: on)",
    )
    p.add_argument("-o", "--output", type=Path, help="map file (default: print it)")
    p.add_argument("--scenario", type=Path, help="also write a BDI scenario for the map")
    p.add_argument("--agent-file", type=Path, help="the robots' agent file (default: recycler)")
    args = p.parse_args(argv)
    try:
        w, h = _size(args.size)
        recipe = Recipe(
            width=w,
            height=h,
            wall_fraction=args.walls,
            bins=args.bins,
            litter=args.litter,
            people=args.people,
            agents=args.agents,
            move_step=args.move_step,
            bottleneck=args.bottleneck,
        )
        text = generate_map(args.seed, recipe)
    except (ValueError, GridError) as exc:
        print(f"cbdi map: {exc}", file=sys.stderr)
        return 2
    if args.output is None:
        print(text, end="")
        if args.scenario is not None:
            print("cbdi map: --scenario needs --output (the map file)", file=sys.stderr)
            return 2
        return 0
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(text, encoding="utf-8")
    if args.scenario is not None:
        agent_file = args.agent_file or _default_agent_file()
        args.scenario.parent.mkdir(parents=True, exist_ok=True)
        args.scenario.write_text(
            scenario_text(args.output, args.scenario, args.agents, agent_file), encoding="utf-8"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
