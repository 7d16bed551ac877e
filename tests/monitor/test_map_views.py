"""The rerun log draws a map that is a graph: its links as line strips, its places as
labelled points, into a real recording (kept in memory)."""

from __future__ import annotations

from typing import Any

import pytest
from cbdi_courier.floor import load_floor

from cbdi import keys
from cbdi.wire import encode
from cbdi.wire.world import MapLayer, MapLink, MapPlace, MapView, WorldInfo
from cbdi_monitor.reader import RecordedMessage
from cbdi_monitor.rerun_log import RerunLogger
from cbdi_monitor.schemas import peek_schema
from tests_support import REPO

rr = pytest.importorskip("rerun")


class Kept:
    """A rerun recording stream in memory that also keeps what was logged, by path."""

    def __init__(self) -> None:
        self.stream = rr.RecordingStream("cbdi-test")
        self.memory = self.stream.memory_recording()
        self.logged: dict[str, tuple[Any, bool]] = {}

    def log(self, path: str, entity: Any, static: bool = False) -> None:
        self.stream.log(path, entity, static=static)
        self.logged[path] = (entity, static)

    def set_time(self, *args: Any, **kw: Any) -> None:
        self.stream.set_time(*args, **kw)


def info_of(view: MapView) -> RecordedMessage:
    info = WorldInfo(map_name="m", agents=["robot1"], epoch_duration=1.0, durations={}, view=view)
    payload = encode(info)
    return RecordedMessage(
        keys.world_stream("info"), payload, 1, 1, 1, peek_schema(payload), "msgpack"
    )


def values(batch: Any) -> list[Any]:
    return list(batch.as_arrow_array().to_pylist())


def test_a_graph_is_drawn_as_links_and_labelled_places() -> None:
    view = MapView(
        width=6,
        height=4,
        layers=[MapLayer(name="walls", cells=[(3, 3)])],
        places=[
            MapPlace(name="shed", at=(0.5, 0.5)),
            MapPlace(name="beds", at=(5.5, 0.5)),
            MapPlace(name="pond", at=(5.5, 3.5)),
        ],
        links=[MapLink(a="shed", b="beds"), MapLink(a="beds", b="pond")],
    )
    kept = Kept()
    logger = RerunLogger(rr, kept)
    logger.handle(info_of(view))
    assert logger.skipped == 0
    links, static = kept.logged["world/graph/links"]
    assert static and values(links.strips) == [
        [[0.5, 0.5], [5.5, 0.5]],
        [[5.5, 0.5], [5.5, 3.5]],
    ]
    places, _ = kept.logged["world/graph/places"]
    assert values(places.labels) == ["shed", "beds", "pond"]
    assert values(places.positions) == [[0.5, 0.5], [5.5, 0.5], [5.5, 3.5]]
    assert {"world/map/floor", "world/map/walls"} <= set(kept.logged)
    kept.stream.flush()
    assert kept.memory.num_msgs() > 0 and kept.memory.drain_as_bytes()  # a real recording


def test_a_map_without_a_graph_draws_none_and_courier_draws_its_links() -> None:
    kept = Kept()
    logger = RerunLogger(rr, kept)
    logger.handle(info_of(MapView(width=2, height=2, layers=[MapLayer(name="walls", cells=[])])))
    assert not any(p.startswith("world/graph") for p in kept.logged)
    floor = load_floor(REPO / "domains/courier/maps/office-11x7.toml")
    logger.handle(info_of(floor.view()))
    links, _ = kept.logged["world/graph/links"]
    strips = values(links.strips)
    assert len(strips) == 49 and [[4.5, 2.5], [5.5, 2.5]] in strips  # through the door
