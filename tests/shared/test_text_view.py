"""The text view: the grid, and what each agent intends from its desire events."""

from __future__ import annotations

from cbdi.view import Intentions, render
from cbdi.wire.agent import DesireEvent
from cbdi.wire.world import (
    AgentView,
    ItemView,
    MapLayer,
    MapView,
    PersonView,
    WorldInfo,
    WorldSnapshot,
)


def event(what: str, desire: str = "recycle", goal: tuple[str, ...] = ("p1",)) -> DesireEvent:
    return DesireEvent(
        agent="robot1",
        desire=desire,
        event=what,
        reason="deadline passed" if what == "dropped" else "",
        time=1.0,
        goal=[["recycled", g] for g in goal],
    )


def test_the_view_shows_the_grid_and_what_each_agent_intends() -> None:
    info = WorldInfo(
        map_name="m",
        agents=["robot1"],
        epoch_duration=1.0,
        durations={"move": 1.0},
        view=MapView(
            width=3,
            height=2,
            layers=[
                MapLayer(name="walls", cells=[(2, 0)]),
                MapLayer(name="bins", cells=[(0, 0)], labels=["bin"], glyph="B"),
            ],
        ),
    )
    snap = WorldSnapshot(
        epoch=4,
        time=4.0,
        agents=[AgentView(name="robot1", cell=(1, 1), pose=(1.0, 1.0), load=["p2"])],
        people=[PersonView(name="p", cell=(0, 1), pose=(0.0, 1.0))],
        items=[ItemView(name="p1", cell=(1, 0), known=True)],
        completed=[],
    )
    intentions = Intentions()
    intentions.on_event(event("activated"))
    intentions.on_event(event("boosted", goal=("p1", "p2")))
    intentions.on_event(event("boosted", desire="patrol"))  # not the one pursued
    text = render(info, snap, intentions.text)
    lines = text.splitlines()
    assert lines[1:3] == ["B * #", "@ 1 ."]
    assert "1=robot1 carrying 1" in lines[3]
    assert lines[4] == "robot1: intends recycle (recycled p1) (recycled p2)"
    intentions.on_event(event("dropped"))
    assert intentions.text["robot1"] == "dropped recycle (deadline passed)"


def test_a_map_without_a_view_is_drawn_as_big_as_what_moves_on_it() -> None:
    """A domain whose map is no floor of cells (`view` None) still gets its robots and
    items drawn, on a grid that holds every cell of the snapshot."""
    info = WorldInfo(map_name="graph", agents=["robot1"], epoch_duration=1.0, durations={})
    snap = WorldSnapshot(
        epoch=1,
        time=1.0,
        agents=[AgentView(name="robot1", cell=(2, 0), pose=(2.5, 0.5))],
        people=[],
        items=[ItemView(name="p1", cell=(0, 1), known=False)],
        completed=[],
    )
    lines = render(info, snap).splitlines()
    assert lines[1:3] == [". . 1", "+ . ."] and lines[3] == "1=robot1"
