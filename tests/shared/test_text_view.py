"""The text view: the grid, and what each agent intends from its desire events."""

from __future__ import annotations

from cbdi_courier.floor import load_floor

from cbdi.view import Intentions, render
from cbdi.wire.agent import DesireEvent
from cbdi.wire.world import (
    AgentView,
    ItemView,
    MapLayer,
    MapLink,
    MapPlace,
    MapView,
    PersonView,
    WorldInfo,
    WorldSnapshot,
)
from tests_support import REPO


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


def greenhouse() -> MapView:
    """A graph of four places: a shed linked to the beds (a row), to the pond (a
    diagonal), the beds to the pond (a column); the tap stands alone."""
    return MapView(
        width=7,
        height=5,
        places=[
            MapPlace(name="shed", at=(0.5, 0.5)),
            MapPlace(name="beds", at=(6.5, 0.5)),
            MapPlace(name="pond", at=(6.5, 4.5)),
            MapPlace(name="tap", at=(0.5, 4.5), glyph="T"),
        ],
        links=[
            MapLink(a="shed", b="beds"),
            MapLink(a="beds", b="pond"),
            MapLink(a="shed", b="pond"),
        ],
    )


def test_a_graph_is_drawn_as_places_and_links_and_named_below() -> None:
    info = WorldInfo(
        map_name="greenhouse", agents=["robot1"], epoch_duration=1.0, durations={},
        view=greenhouse(),
    )  # fmt: skip
    snap = WorldSnapshot(
        epoch=2,
        time=2.0,
        agents=[AgentView(name="robot1", cell=(6, 4), pose=(6.5, 4.5))],
        people=[],
        items=[],
        completed=[],
    )
    lines = render(info, snap).splitlines()
    assert lines[1:6] == [
        "o - - - - - o",
        ". \\ \\ . . . |",
        ". . . \\ . . |",
        ". . . . \\ \\ |",
        "T . . . . . 1",
    ]
    assert lines[6] == "1=robot1"
    assert lines[7] == "places: shed 0,0  beds 6,0  pond 6,4  tap 0,4"
    assert lines[8] == "links: shed-beds  beds-pond  shed-pond"


def test_a_floor_of_cells_that_is_also_a_graph_is_counted_not_listed() -> None:
    """Courier's floor: every floor cell a place drawn as floor, walls over the graph;
    too many places to name, so the legend counts them."""
    view = load_floor(REPO / "domains/courier/maps/office-11x7.toml").view()
    info = WorldInfo(map_name="office", agents=[], epoch_duration=1.0, durations={}, view=view)
    snap = WorldSnapshot(epoch=0, time=0.0, agents=[], people=[], items=[], completed=[])
    lines = render(info, snap).splitlines()
    assert lines[1:4] == ["# # # # # # # # # # #", "# . . . # . . . . . #", "# . . . . . . . . . #"]
    assert ("c_4_2", "c_5_2") in {(link.a, link.b) for link in view.links}  # the door
    assert lines[-1] == f"graph: {len(view.places)} places, {len(view.links)} links"
    assert len(view.places) == 36 and len(view.links) == 49
