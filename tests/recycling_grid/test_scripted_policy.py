"""The scripted agent's policy: shortest hops, the greedy recycling loop, script parsing."""

from __future__ import annotations

import pytest
from cbdi_recycling.scripted.policy import Beliefs, Step, greedy_step, next_hop, parse_script
from cbdi_recycling.wire import Percepts

from cbdi.wire.world import (
    ItemView,
)


def beliefs(**kw: object) -> Beliefs:
    b = Beliefs(width=5, height=3, walls=frozenset({(2, 0), (2, 1)}), bins=frozenset({(0, 0)}))
    for k, v in kw.items():
        setattr(b, k, v)
    return b


def test_next_hop_goes_around_walls_and_people() -> None:
    b = beliefs(position=(1, 0))
    assert next_hop(b, [(3, 0)]) == (1, 1)  # the wall column forces the way down
    b.blocked = {(1, 1)}
    assert next_hop(b, [(3, 0)]) is None  # (1,1) blocked: no way through now
    assert next_hop(b, [(1, 0)]) is None  # already there


def test_greedy_fetches_picks_up_returns_and_recycles() -> None:
    b = beliefs(position=(1, 0), litter={"p": (3, 2)})
    assert greedy_step(b) == Step("move", target=(1, 1))
    b.position = (3, 2)
    assert greedy_step(b) == Step("pickup", item="p")
    b.litter, b.holding = {}, ("p",)
    assert greedy_step(b).action == "move"  # type: ignore[union-attr]
    b.position = (1, 0)
    assert greedy_step(b) == Step("recycle", item="p")


def test_greedy_explores_unsensed_cells_then_rests() -> None:
    b = beliefs(position=(0, 1))
    assert greedy_step(b) is not None
    b.sensed = {(x, y) for x in range(5) for y in range(3)}
    assert greedy_step(b) is None


def test_percepts_revise_litter_and_blocked_cells() -> None:
    b = beliefs(position=(0, 1), litter={"gone": (1, 1), "far": (4, 2)})
    p = Percepts(
        agent="r",
        epoch=1,
        time=1.0,
        position=(0, 1),
        depth=1,
        free=[(1, 1)],
        blocked=[(0, 0), (1, 0), (0, 2)],
        holding=[],
        items=[ItemView(name="new", cell=(0, 2), known=False)],
    )
    b.revise(p)
    assert b.litter == {"far": (4, 2), "new": (0, 2)}  # sensed empty cell clears "gone"
    assert b.blocked == {(1, 0), (0, 2)}  # the bin is static, not an obstacle that moves
    assert (1, 1) in b.sensed


def test_parse_script() -> None:
    assert parse_script("move:1,2; pickup recycle:x") == [
        Step("move", target=(1, 2)),
        Step("pickup"),
        Step("recycle", item="x"),
    ]
    with pytest.raises(ValueError, match="move:X,Y"):
        parse_script("move:1")
    with pytest.raises(ValueError, match="expected"):
        parse_script("dance")
