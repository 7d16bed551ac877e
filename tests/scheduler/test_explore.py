"""Exploring: a recycler idle for a while goes to the nearest cell it never sensed, so
litter nobody has seen is found (8 robots on campus-30x30 left one item unseen for 960 s)."""

from __future__ import annotations

from cbdi_recycling.events import exploration_target, map_beliefs
from cbdi_recycling.knowledge import EXPLORE_AFTER, RecyclingKnowledge
from cbdi_recycling.wire import Percepts

from cbdi.beliefs import BeliefSet
from cbdi.wire.world import (
    ItemView,
    WorldInfo,
)
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.mind import Mind
from tests_support import REPO, grid_info

AGENT = REPO / "domains/recycling/agents/recycler.toml"


def info() -> WorldInfo:
    # A 4x3 room with a wall at (1, 1) and a bin at (3, 2).
    return grid_info(4, 3, [(1, 1)], {"bin1": (3, 2)}, map_name="room")


def seen(time: float, at: tuple[int, int], free: list[tuple[int, int]]) -> Percepts:
    return Percepts(
        agent="robot1",
        epoch=int(time),
        time=time,
        position=at,
        depth=1,
        free=free,
        blocked=[],
        holding=[],
        items=[],
    )


def targets(beliefs: BeliefSet) -> list[tuple[str, ...]]:
    return sorted(beliefs.facts_of("explore_target"))


def test_the_target_is_the_nearest_unsensed_cell_and_kept_until_reached() -> None:
    k = RecyclingKnowledge("robot1")
    beliefs = BeliefSet.of(map_beliefs(info()))
    beliefs = k.on_percepts(beliefs, seen(0, (0, 0), [(1, 0), (0, 1)]))
    assert targets(beliefs) == []  # idle only a moment: not yet
    beliefs = k.on_percepts(beliefs, seen(EXPLORE_AFTER, (0, 0), [(1, 0), (0, 1)]))
    assert targets(beliefs) == [("explore_target", "c_0_2")]  # 2 steps, as (2, 0): by name
    beliefs = k.on_percepts(beliefs, seen(11, (0, 1), [(0, 0), (0, 2)]))
    assert targets(beliefs) == [("explore_target", "c_0_2")]  # sensed, not reached: kept
    beliefs = k.on_percepts(beliefs, seen(12, (0, 2), [(0, 1), (1, 2)]))
    assert targets(beliefs) == [("explore_target", "c_2_2")]  # reached: the next, 2 steps
    beliefs = k.on_percepts(beliefs, seen(13, (1, 2), [(0, 2), (2, 2)]))
    assert targets(beliefs) == [("explore_target", "c_2_2")]  # on its way
    person = Percepts(
        agent="robot1",
        epoch=14,
        time=14.0,
        position=(1, 2),
        depth=1,
        free=[(0, 2)],
        blocked=[(2, 2)],
        holding=[],
        items=[],
    )
    beliefs = k.on_percepts(beliefs, person)
    assert targets(beliefs) == [("explore_target", "c_2_1")]  # seen blocked: the next
    everything = [(x, y) for x in range(4) for y in range(3) if (x, y) not in ((1, 1), (3, 2))]
    beliefs = k.on_percepts(beliefs, seen(13, (2, 0), everything))
    assert targets(beliefs) == []  # all sensed: nothing to explore


def test_exploring_stops_when_the_robot_picks_something_up() -> None:
    k = RecyclingKnowledge("robot1")
    beliefs = BeliefSet.of(map_beliefs(info()))
    for t in (0, EXPLORE_AFTER):
        beliefs = k.on_percepts(beliefs, seen(t, (0, 0), [(1, 0)]))
    assert targets(beliefs)
    holding = Percepts(
        agent="robot1",
        epoch=11,
        time=11.0,
        position=(1, 0),
        depth=1,
        free=[],
        blocked=[],
        holding=["pla1"],
        items=[],
    )
    assert targets(k.on_percepts(beliefs, holding)) == []


def test_bins_and_unreachable_cells_are_never_targets() -> None:
    lengths = {"c_0_0": 0, "c_1_0": 1, "c_2_0": 2}
    assert exploration_target(lengths, {"c_0_0"}, {"c_1_0"}) == "c_2_0"
    assert exploration_target(lengths, {"c_0_0", "c_2_0"}, {"c_1_0"}) is None


def test_an_idle_robot_explores_and_recycling_comes_first() -> None:
    mind = Mind(load_agent(AGENT, "robot1"))
    mind.beliefs = mind.beliefs.adding(map_beliefs(info()))
    mind.on_percepts(seen(0, (0, 0), [(1, 0), (0, 1)]))
    out = mind.on_percepts(seen(EXPLORE_AFTER, (0, 0), [(1, 0), (0, 1)]))
    assert ("explore_c_0_2", "activated") in [(e.desire, e.event) for e in out.events]
    assert out.commands[-1].kind == "start_search"
    spotted = Percepts(
        agent="robot1",
        epoch=11,
        time=11.0,
        position=(0, 0),
        depth=1,
        free=[(1, 0), (0, 1)],
        blocked=[],
        holding=[],
        items=[ItemView(name="pla1", cell=(0, 1))],
    )
    out = mind.on_percepts(spotted)
    assert ("recycle", "activated") in [(e.desire, e.event) for e in out.events]
