"""Generated maps: a function of the seed, valid, connected, a bin behind one cell that a
person crosses; `cbdi map` writes a map and a scenario that `cbdi up` reads."""

from __future__ import annotations

from collections import deque
from pathlib import Path

import pytest
from cbdi_recycling.generate import Recipe, generate_map, main
from cbdi_recycling.maps import parse_map

from cbdi.launcher.scenario import load_scenario


def reachable(free: set[tuple[int, int]], start: tuple[int, int]) -> set[tuple[int, int]]:
    seen, todo = {start}, deque([start])
    while todo:
        x, y = todo.popleft()
        for n in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
            if n in free and n not in seen:
                seen.add(n)
                todo.append(n)
    return seen


@pytest.mark.parametrize("seed", range(1, 21))
def test_every_seed_gives_a_connected_map_with_a_bottleneck_a_person_crosses(seed: int) -> None:
    text = generate_map(seed, Recipe(agents=2))
    assert generate_map(seed, Recipe(agents=2)) == text  # a function of the seed
    m = parse_map(text)
    cells = {(x, y) for y in range(m.height) for x in range(m.width)}
    free = cells - m.walls - set(m.bins.values())
    assert reachable(free, m.agent_starts[0]) == free  # every free cell reachable
    assert len(m.agent_starts) == 2 and len(m.litter) == 4 and len(m.people) == 2
    (bin_cell,) = m.bins.values()
    x, y = bin_cell
    access = [n for n in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)) if n in free]
    assert len(access) == 1  # the only cell to recycle from
    a = access[0]
    ways_in = [n for n in ((a[0] + 1, a[1]), (a[0] - 1, a[1]), (a[0], a[1] + 1), (a[0], a[1] - 1))]
    assert len([n for n in ways_in if n in free]) >= 2  # not a dead end
    assert a in m.people[0].path  # a person walks across it
    on_loops = {c for p in m.people for c in p.path}
    assert not on_loops & set(m.agent_starts)


def test_other_recipes_and_bad_ones() -> None:
    m = parse_map(generate_map(3, Recipe(width=15, height=11, bins=2, litter=6, people=3)))
    assert (m.width, m.height, len(m.bins), len(m.litter), len(m.people)) == (15, 11, 2, 6, 3)
    open_map = parse_map(generate_map(3, Recipe(bottleneck=False, wall_fraction=0.0)))
    assert not open_map.walls
    with pytest.raises(ValueError, match="size"):
        generate_map(1, Recipe(width=2))
    with pytest.raises(ValueError, match="wall fraction"):
        generate_map(1, Recipe(wall_fraction=0.9))


def test_the_command_writes_a_map_and_a_scenario(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, scen = tmp_path / "maps" / "g.toml", tmp_path / "g-bdi.toml"
    assert main(["--seed", "4", "--agents", "2", "-o", str(out), "--scenario", str(scen)]) == 0
    s = load_scenario(scen)
    assert [a.kind for a in s.agents] == ["bdi", "bdi"] and s.run.lockstep
    assert parse_map(out.read_text()).name == "generated-4"
    assert main(["--seed", "4", "--size", "2x2"]) == 2
    assert "size 2x2" in capsys.readouterr().err
    assert main(["--seed", "4", "--size", "9y9"]) == 2
    assert "expected WIDTHxHEIGHT" in capsys.readouterr().err
    assert main(["--seed", "4", "--size", "4x4", "--litter", "30"]) == 2
    assert "no room for 30 litter items" in capsys.readouterr().err
