"""The scheduler's pure core: beliefs, DNF conditions, desires, reactive rules, percepts."""

from __future__ import annotations

import pytest
from cbdi_recycling.events import revise_from_percepts
from cbdi_recycling.wire import Percepts
from msgspec.structs import replace

from cbdi.beliefs import Belief, BeliefSet, fact, fluent, instance
from cbdi.wire.world import (
    ItemView,
)
from cbdi_scheduler.conditions import Literal, bindings, holds
from cbdi_scheduler.desires import Desire, achieved, drops, select_desire
from cbdi_scheduler.rules import ReactiveRule, RuleEffect, fire_rules

WORLD = BeliefSet.of(
    [
        fact("map_loaded"),
        instance("pla61", "plastic"),
        instance("pla36", "plastic"),
        instance("robot", "agent"),
        fact("litter_pose", "pla61", "c_6_1"),
        fact("litter_pose", "pla36", "c_3_6"),
        fact("in", "robot", "c_0_1"),
        fluent("loaded_amount", "robot", value=1),
    ]
)


def lit(check: str, b: Belief, value: float = 0.0) -> Literal:
    return Literal(check, b, value)


def test_belief_sets_are_values() -> None:
    more = WORLD.adding([fact("free", "c_1_1")])
    assert more.holds(fact("free", "c_1_1")) and not WORLD.holds(fact("free", "c_1_1"))
    assert more.removing([fact("free", "c_1_1")]) == WORLD
    assert (
        WORLD.adding([fluent("loaded_amount", "robot", value=2)]).fluents[
            ("loaded_amount", "robot")
        ]
        == 2
    )
    assert str(fact("in", "robot", "c_0_1")) == "(in robot c_0_1)"
    with pytest.raises(ValueError):
        Belief("opinion", "x")


def test_conditions_bind_every_placeholder() -> None:
    litter = ((lit("EX", instance("{x}", "plastic")), lit("T", fact("litter_pose", "{x}", "*"))),)
    assert bindings(litter, WORLD) == [{"x": "pla36"}, {"x": "pla61"}]
    where = ((lit("T", fact("litter_pose", "{x}", "{c}")),),)
    assert {"x": "pla61", "c": "c_6_1"} in bindings(where, WORLD)


def test_false_exists_and_numeric_checks() -> None:
    assert holds(((lit("F", fact("holding", "robot", "*")),),), WORLD)
    assert not holds(((lit("F", fact("litter_pose", "pla61", "*")),),), WORLD)
    assert holds(((lit("LT", fluent("loaded_amount", "robot", value=0), 3),),), WORLD)
    assert not holds(((lit("GE", fluent("loaded_amount", "{a}", value=0), 2),),), WORLD)
    assert not holds(((lit("EX", instance("pla99", "plastic")),),), WORLD)


def test_disjunction_and_conjunction() -> None:
    never = (lit("T", fact("nothing")),)
    always = (lit("T", fact("map_loaded")),)
    assert holds((never, always), WORLD)
    assert not holds(((*always, *never),), WORLD)
    assert holds((), WORLD)  # the empty condition is true
    with pytest.raises(ValueError, match="unknown check"):
        lit("MAYBE", fact("x"))
    with pytest.raises(ValueError, match="needs a instance"):
        lit("EX", fact("x"))


def recycle(*items: str, priority: float = 0.8) -> Desire:
    return Desire("recycle", tuple(fact("recycled", i) for i in items), priority, 64.0)


def test_goal_reasoner_prefers_priority_and_checks_preconditions() -> None:
    patrol = Desire("patrol", (fact("in", "robot", "c_6_6"),), 0.1, 100.0)
    gated = Desire(
        "urgent", (fact("done"),), 0.9, 100.0, precondition=((lit("T", fact("alarm")),),)
    )
    held = {"patrol": patrol, "recycle": recycle("pla61"), "urgent": gated}
    assert select_desire(held, WORLD, now=0).name == "recycle"  # type: ignore[union-attr]
    alarmed = WORLD.adding([fact("alarm")])
    assert select_desire(held, alarmed, now=0).name == "urgent"  # type: ignore[union-attr]
    assert select_desire(held, WORLD, now=70).name == "patrol"  # type: ignore[union-attr]
    done = WORLD.adding([fact("recycled", "pla61")])
    assert achieved(held["recycle"], done)
    assert select_desire({"recycle": held["recycle"]}, done, now=0) is None


def test_drops_name_the_reason() -> None:
    careful = Desire(
        "careful", (fact("x"),), 0.5, 100.0, context=((lit("T", fact("map_loaded")),),)
    )
    held = {"recycle": recycle("pla61"), "careful": careful}
    assert drops(held, WORLD, now=10, active="careful") == []
    gone = drops(held, WORLD.removing([fact("map_loaded")]), now=70, active="careful")
    assert [(d.desire, d.reason.split()[0]) for d in gone] == [
        ("careful", "context"),
        ("recycle", "deadline"),
    ]


PAPER_RULES = [
    ReactiveRule(
        name="sensed_litter",
        condition=(
            (
                lit("T", fact("map_loaded")),
                lit("EX", instance("{x}", "plastic")),
                lit("T", fact("litter_pose", "{x}", "*")),
            ),
        ),
        effects=(
            RuleEffect(
                "desire", "BOOST", desire=Desire("recycle", (fact("recycled", "{x}"),), 0.8, 64.0)
            ),
        ),
    ),
    ReactiveRule(
        name="patrol",
        condition=((lit("T", fact("map_loaded")), lit("T", fact("should_patrol", "{x}"))),),
        effects=(
            RuleEffect("belief", "DEL", belief=fact("should_patrol", "{x}")),
            RuleEffect(
                "desire",
                "ADD",
                desire=Desire("patrol_{x}", (fact("in", "robot", "{x}"),), 0.1, 64.0),
            ),
        ),
    ),
]


def test_paper_rules_boost_the_goal_with_each_sensed_item() -> None:
    out = fire_rules(PAPER_RULES, WORLD, {}, now=5.0)
    goal = out.desires["recycle"].goal
    assert set(goal) == {fact("recycled", "pla61"), fact("recycled", "pla36")}
    assert out.desires["recycle"].deadline == 69.0  # relative deadline made absolute
    sensed = WORLD.adding([instance("pla46", "plastic"), fact("litter_pose", "pla46", "c_4_6")])
    again = fire_rules(PAPER_RULES, sensed, out.desires, now=9.0)
    assert fact("recycled", "pla46") in again.desires["recycle"].goal
    assert again.boosted == ["recycle"]
    assert again.desires["recycle"].deadline == 73.0  # the new item's span from 9
    assert fire_rules(PAPER_RULES, WORLD, out.desires, now=9).boosted == []  # nothing new


def test_patrol_rule_deletes_a_belief_and_adds_a_desire_per_binding() -> None:
    beliefs = WORLD.adding([fact("should_patrol", "c_6_6"), fact("should_patrol", "c_0_6")])
    out = fire_rules(PAPER_RULES[1:], beliefs, {}, now=0)
    assert sorted(out.desires) == ["patrol_c_0_6", "patrol_c_6_6"]
    assert out.desires["patrol_c_6_6"].goal == (fact("in", "robot", "c_6_6"),)
    assert not any(a[0] == "should_patrol" for a in out.beliefs.facts)
    assert len(out.fired) == 2


def test_percepts_revise_the_sensed_square_only() -> None:
    before = BeliefSet.of(
        [
            fact("free", "c_1_1"),
            fact("free", "c_5_5"),
            fact("litter_pose", "old", "c_1_0"),
            fact("litter_pose", "far", "c_6_6"),
            fact("in", "robot", "c_9_9"),
        ]
    )
    p = Percepts(
        agent="robot",
        epoch=3,
        time=3.0,
        position=(0, 1),
        depth=1,
        free=[(1, 0), (0, 2)],
        blocked=[(0, 0), (1, 1), (1, 2)],
        holding=["pla9"],
        items=[ItemView(name="new", cell=(0, 2), known=False)],
    )
    after = revise_from_percepts(before, p)
    assert after.holds(fact("free", "c_1_0")) and after.holds(fact("free", "c_0_2"))
    assert not after.holds(fact("free", "c_1_1"))  # a person stands there now
    assert after.holds(fact("free", "c_5_5"))  # outside the square: unchanged
    assert not after.holds(fact("litter_pose", "old", "c_1_0"))  # seen to be gone
    assert after.holds(fact("litter_pose", "far", "c_6_6"))
    assert after.holds(fact("litter_pose", "new", "c_0_2"))
    assert after.holds(instance("new", "plastic"))
    assert after.holds(fact("in", "robot", "c_0_1")) and not after.holds(
        fact("in", "robot", "c_9_9")
    )
    assert after.holds(fact("holding", "robot", "pla9"))
    assert after.fluents[("loaded_amount", "robot")] == 1


def test_an_obstacle_out_of_sight_is_forgotten_but_bins_stay() -> None:
    cells = [instance(f"c_{x}_0", "cell") for x in range(6)]
    before = BeliefSet.of([*cells, fact("bin_pose", "bin", "c_5_0"), fact("free", "c_1_0")])
    seen = Percepts(
        agent="robot",
        epoch=1,
        time=1.0,
        position=(0, 0),
        depth=1,
        free=[],
        blocked=[(1, 0)],  # a person next to the robot
        holding=[],
        items=[],
    )
    after = revise_from_percepts(before, seen)
    assert not after.holds(fact("free", "c_1_0"))
    assert all(after.holds(fact("free", f"c_{x}_0")) for x in (2, 3, 4))  # assumed free
    assert not after.holds(fact("free", "c_5_0"))  # the bin
    moved = replace(seen, epoch=2, position=(3, 0), blocked=[(2, 0)])
    later = revise_from_percepts(after, moved)
    assert later.holds(fact("free", "c_1_0"))  # the person was left behind, out of sight
    assert not later.holds(fact("free", "c_2_0"))


def test_map_beliefs_describe_the_grid() -> None:
    from cbdi_recycling.events import map_beliefs

    from tests_support import grid_info

    info = grid_info(3, 2, [(1, 0)], {"bin_0_0": (0, 0)}, ("r",))
    beliefs = BeliefSet.of(map_beliefs(info))
    assert beliefs.holds(fact("map_loaded")) and beliefs.holds(instance("c_2_1", "cell"))
    assert not beliefs.holds(instance("c_1_0", "cell"))  # a wall is no cell
    assert beliefs.holds(fact("near", "c_0_0", "c_0_1"))
    assert not beliefs.holds(fact("near", "c_0_0", "c_1_0"))  # not into the wall
    assert beliefs.holds(fact("bin_pose", "bin_0_0", "c_0_0"))
    assert not beliefs.holds(fact("free", "c_0_0")) and beliefs.holds(fact("free", "c_2_0"))


def test_an_obstacle_out_of_sight_is_remembered_for_a_while() -> None:
    """Forgotten at once, a blocked short way out of sight looked free again, and a robot
    turned back and forth between it and a detour (seen with three robots on 7x7)."""
    from cbdi_recycling.events import OBSTACLE_MEMORY, seen_blocked

    cells = [instance(f"c_{x}_0", "cell") for x in range(6)]
    before = BeliefSet.of([*cells, fact("free", "c_1_0")])
    seen = Percepts(
        agent="robot",
        epoch=1,
        time=1.0,
        position=(0, 0),
        depth=1,
        free=[],
        blocked=[(1, 0)],
        holding=[],
        items=[],
    )
    memory = seen_blocked({}, seen)
    after = revise_from_percepts(before, seen, blocked=memory)
    moved = replace(seen, epoch=2, time=2.0, position=(3, 0), free=[(2, 0), (4, 0)], blocked=[])
    memory = seen_blocked(memory, moved)
    later = revise_from_percepts(after, moved, blocked=memory)
    assert not later.holds(fact("free", "c_1_0"))  # out of sight, still believed blocked
    gone = replace(moved, epoch=10, time=1.0 + OBSTACLE_MEMORY)
    memory = seen_blocked(memory, gone)
    assert memory == {}
    assert revise_from_percepts(later, gone, blocked=memory).holds(fact("free", "c_1_0"))
    back = replace(seen, epoch=3, time=3.0, free=[(1, 0)], blocked=[])
    assert seen_blocked(seen_blocked({}, seen), back) == {}  # seen free again: forgotten
