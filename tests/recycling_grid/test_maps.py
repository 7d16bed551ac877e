"""Map files: every shipped map loads; every kind of mistake names file, field and reason."""

from __future__ import annotations

from pathlib import Path

import pytest
from cbdi_recycling.errors import MapError
from cbdi_recycling.maps import load_map, parse_map

MAPS = Path(__file__).resolve().parents[2] / "domains" / "recycling" / "maps"


@pytest.mark.parametrize("path", sorted(MAPS.glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_map_loads(path: Path) -> None:
    m = load_map(path)
    assert m.agent_starts and m.bins and m.name == path.stem


def test_paper_map_matches_the_paper() -> None:
    m = load_map(MAPS / "paper-7x7.toml")
    assert (m.width, m.height) == (7, 7)
    assert m.bins == {"bin_0_0": (0, 0)} and m.agent_starts[0] == (0, 1)
    assert m.walls == {(1, 3), (1, 4), (4, 1), (5, 1), (4, 2), (5, 2), (4, 4), (5, 4)}
    assert {c for c, _ in m.litter.values()} == {(6, 1), (4, 6), (3, 6)}
    assert [len(p.path) for p in m.people] == [20, 12]
    assert [p.path[0] for p in m.people] == [(4, 0), (6, 3)]
    assert all(p.move_step == 4 for p in m.people)
    k2 = load_map(MAPS / "paper-7x7-k2.toml")
    assert sorted(n for n, (_, known) in k2.litter.items() if not known) == ["plastic_4_6"]


def test_larger_maps_have_room_for_many_agents() -> None:
    assert len(load_map(MAPS / "warehouse-15x15.toml").agent_starts) >= 8
    campus = load_map(MAPS / "campus-30x30.toml")
    assert len(campus.agent_starts) >= 16 and len(campus.people) >= 8 and len(campus.litter) >= 20


BASE = 'name = "t"\ngrid = """\nBA..\n....\n"""\n'


@pytest.mark.parametrize(
    ("text", "field", "reason"),
    [
        ('name = "t"\ngrid = """\nBA..\n...\n"""\n', "grid row 1", "has 3 cells"),
        ('name = "t"\ngrid = """\nBA.?\n....\n"""\n', "grid row 0 column 3", "unknown cell"),
        ('name = "t"\ngrid = """\nB...\n....\n"""\n', "grid", "no agent start"),
        ('name = "t"\ngrid = """\n.A..\n....\n"""\n', "grid", "no bin"),
        ('grid = """\nBA..\n"""\n', "name", "missing"),
        (BASE + "[litter]\nspawn_probability = 2\n", "litter.spawn_probability", "expected 0..1"),
        (BASE + "[durations]\nfly = 1\n", "durations", "unknown actions"),
        (BASE + "[agents]\ndetection_depth = -1\n", "agents.detection_depth", "integer >= 0"),
        (BASE + "[[people]]\nmove_step = 0\npath = [[2, 1]]\n", "people[0].move_step", ">= 1"),
        (
            BASE + "[[people]]\nmove_step = 1\npath = [[2, 1], [3, 0]]\n",
            "people[0].path[1]",
            "is not next to",
        ),
        (
            BASE + "[[people]]\nmove_step = 1\npath = [[2, 1], [9, 1]]\n",
            "people[0].path[1]",
            "outside the 4x2 map",
        ),
        (
            BASE + "[[people]]\nmove_step = 1\npath = [[0, 0]]\n",
            "people[0].path[0]",
            "wall or a bin",
        ),
        (
            BASE + "[[people]]\nmove_step = 1\npath = [[1, 1], [2, 1], [3, 1], [3, 0]]\n",
            "people[0].path",
            "not closed",
        ),
        (BASE + "[[people]]\nmove_step = 1\npath = [[1, 0]]\n", "people[0].path[0]", "agent start"),
        (BASE + "[[people]]\nmove_step = 1\npath = 'x'\n", "people[0].path", "list of [x, y]"),
        ("grid = = 1", "toml", ""),
    ],
)
def test_map_errors_name_the_field(text: str, field: str, reason: str) -> None:
    with pytest.raises(MapError) as err:
        parse_map(text, "maps/t.toml")
    assert err.value.path == "maps/t.toml"
    assert err.value.field == field
    assert reason in err.value.reason
    assert str(err.value).startswith(f"maps/t.toml: {field}: ")


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(MapError, match="not found"):
        load_map(tmp_path / "none.toml")


def test_situation_overrides_people_depth_and_known_litter() -> None:
    from cbdi_recycling.maps import with_situation

    m = load_map(MAPS / "paper-7x7.toml")
    s = with_situation(m, move_step=8, detection_depth=3, known_litter=2)
    assert [p.move_step for p in s.people] == [8, 8] and s.detection_depth == 3
    known = sorted(n for n, (_, k) in s.litter.items() if k)
    assert known == ["plastic_3_6", "plastic_6_1"]  # the first two in reading order
    assert with_situation(m) == m  # defaults keep the map as it is
    with pytest.raises(MapError, match="known_litter"):
        with_situation(m, known_litter=4)
