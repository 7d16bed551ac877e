"""Claims: robots of one group never pursue the same litter item (pure logic, two minds)."""

from __future__ import annotations

from pathlib import Path

import msgspec
import pytest
from cbdi_recycling.events import UNKNOWN_DISTANCE, distance
from cbdi_recycling.wire import Percepts

from cbdi.beliefs import BeliefSet, fact
from cbdi.wire.agent import Claim
from cbdi.wire.world import (
    ItemView,
)
from cbdi_scheduler.agentfile import load_agent
from cbdi_scheduler.claims import Claims
from cbdi_scheduler.mind import Mind, Reaction

AGENT = Path(__file__).resolve().parents[2] / "domains/recycling/agents/recycler.toml"


def seen(agent: str, epoch: int, *litter: tuple[str, tuple[int, int]]) -> Percepts:
    return Percepts(
        agent=agent,
        epoch=epoch,
        time=float(epoch),
        position=(0, 1),
        depth=1,
        free=[(1, 1)],
        blocked=[(0, 0)],
        holding=[],
        items=[ItemView(name=n, cell=c) for n, c in litter],
    )


def goal(mind: Mind) -> list[tuple[str, ...]]:
    desire = mind.desires.get("recycle")
    return [g.atom for g in desire.goal] if desire else []


def tell(reaction: Reaction, *minds: Mind) -> list[Reaction]:
    return [m.on_claim(c) for c in reaction.claims for m in minds]


def test_the_earliest_claim_owns_an_item_ties_go_to_the_first_name() -> None:
    a = Claims("robot2", "recyclers", frozenset({"recycled"}))
    assert [c.item for c in a.claim([("recycled", "p1"), ("in", "robot2", "c")], 20)] == ["p1"]
    assert a.claim([("recycled", "p1")], 21) == []  # claimed once
    assert a.foreign(("recycled", "p1")) is None
    assert a.on_claim(Claim(agent="robot3", group="recyclers", item="p1", epoch=4))
    assert a.foreign(("recycled", "p1")) == "robot3"  # robot2's claim came too late
    assert a.on_claim(Claim(agent="robot1", group="recyclers", item="p1", epoch=6))
    assert a.owner("p1") == "robot1"  # within the window, same cost: the first name
    assert not a.on_claim(Claim(agent="robot9", group="others", item="p1", epoch=0))
    a.on_claim(Claim(agent="robot1", group="recyclers", item="p1", released=True))
    a.on_claim(Claim(agent="robot3", group="recyclers", item="p1", released=True))
    assert a.owner("p1") == "robot2" and [c.item for c in a.mine()] == ["p1"]


def test_at_the_same_epoch_the_nearest_robot_owns_the_item() -> None:
    a = Claims("robot1", "recyclers", frozenset({"recycled"}))
    a.claim([("recycled", "p1"), ("recycled", "p2")], 0, {"p1": 7.0, "p2": 2.0}.__getitem__)
    a.on_claim(Claim(agent="robot2", group="recyclers", item="p1", epoch=0, cost=3.0))
    a.on_claim(Claim(agent="robot2", group="recyclers", item="p2", epoch=0, cost=5.0))
    assert a.owner("p1") == "robot2" and a.owner("p2") == "robot1"
    a.on_claim(Claim(agent="robot3", group="recyclers", item="p2", epoch=9, cost=0.0))
    assert a.owner("p2") == "robot1"  # a much later claim never takes an item over


def test_a_robot_near_all_the_litter_does_not_get_all_of_it() -> None:
    costs = {"robot1": (8, 9, 8), "robot2": (7, 8, 7), "robot3": (4, 5, 6)}  # the 7x7 map
    items = ("p36", "p46", "p61")
    views = {a: Claims(a, "recyclers", frozenset({"recycled"})) for a in costs}
    sent = []
    for a, view in views.items():
        cost = dict(zip(items, costs[a], strict=True))
        sent += view.claim([("recycled", i) for i in items], 0, cost.__getitem__)
    for view in views.values():
        for claim in sent:
            view.on_claim(claim)
    expected = {"p36": "robot3", "p46": "robot2", "p61": "robot1"}
    assert all(view.assignment() == expected for view in views.values())


def test_distance_follows_the_believed_cells() -> None:
    near = [fact("near", x, y) for x, y in ("ab", "ba", "bc", "cb")]
    beliefs = BeliefSet.of([fact("in", "r", "a"), fact("litter_pose", "p", "c"), *near])
    assert distance(beliefs, "r", "p") == 2.0
    assert distance(beliefs, "r", "elsewhere") == UNKNOWN_DISTANCE
    assert distance(beliefs.adding([fact("holding", "r", "p")]), "r", "p") == 0.0


def test_two_robots_seeing_the_same_litter_share_it_out() -> None:
    r1 = Mind(load_agent(AGENT, "robot1"))
    r2 = Mind(load_agent(AGENT, "robot2"))
    # Both see p1 in the same epoch; robot2 also sees p2.
    out1 = r1.on_percepts(seen("robot1", 0, ("p1", (1, 1))))
    out2 = r2.on_percepts(seen("robot2", 0, ("p1", (1, 1)), ("p2", (1, 2))))
    assert [c.item for c in out1.claims] == ["p1"]
    assert sorted(c.item for c in out2.claims) == ["p1", "p2"]
    tell(out1, r2)
    tell(out2, r1)
    # The claims are weighed at the next cycle, all at once.
    assert goal(r1) == [("recycled", "p1")] and len(goal(r2)) == 2
    r1.on_percepts(seen("robot1", 1, ("p1", (1, 1))))
    lost = r2.on_percepts(seen("robot2", 1, ("p1", (1, 1)), ("p2", (1, 2))))
    assert goal(r1) == [("recycled", "p1")]  # robot1 won the tie on p1
    # robot2 gives up its claim on what it lost: the contest is over (left open, it
    # turned whenever an item done elsewhere changed the loads).
    assert [(c.item, c.released) for c in lost.claims] == [("p1", True)]
    tell(lost, r1)
    assert r1.claims is not None and set(r1.claims.held["p1"]) == {"robot1"}
    assert goal(r2) == [("recycled", "p2")]
    # robot2 searches again for what is left of its goal: a new search, not a union.
    assert r2.claims is not None and r2.claims.owner("p1") == "robot1"


def test_a_robot_whose_whole_goal_is_taken_drops_it_and_the_item_returns_on_release() -> None:
    r1 = Mind(load_agent(AGENT, "robot1"))
    r2 = Mind(load_agent(AGENT, "robot2"))
    out1 = r1.on_percepts(seen("robot1", 0, ("p1", (1, 1))))
    tell(out1, r2)  # robot1 claimed p1 at epoch 0
    out2 = r2.on_percepts(seen("robot2", 1, ("p1", (1, 1))))
    assert out2.claims == [] and "recycle" not in r2.desires  # never taken up
    assert r2.intentions.current is None
    # robot1 gives p1 up (its desire dropped): robot2 takes it.
    r1.desires.pop("recycle")
    assert r1.claims is not None
    released = Reaction(claims=r1.claims.release([("recycled", "p1")]))
    tell(released, r2)
    again = r2.on_percepts(seen("robot2", 2, ("p1", (1, 1))))
    assert [c.item for c in again.claims] == ["p1"] and goal(r2) == [("recycled", "p1")]


def test_losing_part_of_an_active_goal_restarts_the_search_without_it() -> None:
    r2 = Mind(load_agent(AGENT, "robot2"))
    out = r2.on_percepts(seen("robot2", 3, ("p1", (1, 1)), ("p2", (1, 2))))
    assert [c.kind for c in out.commands] == ["start_search"]
    assert r2.on_claim(Claim(agent="robot1", group="recyclers", item="p1", epoch=2)).commands == []
    late = r2.on_percepts(seen("robot2", 4, ("p1", (1, 1)), ("p2", (1, 2))))
    starts = [c for c in late.commands if c.kind == "start_search"]
    assert starts and starts[0].reason == "goal reduced"
    assert starts[0].desire is not None and starts[0].desire.goal == (fact("recycled", "p2"),)
    assert [(e.desire, e.event) for e in late.events] == [("recycle", "reduced")]


def test_a_robot_holding_an_item_owns_it_whatever_else_was_claimed() -> None:
    a = Claims("robot2", "recyclers", frozenset({"recycled"}))
    a.on_claim(Claim(agent="robot1", group="recyclers", item="p1", epoch=0, cost=1.0))
    assert a.claim([("recycled", "p1")], 30, lambda item: 9.0) != []
    assert a.owner("p1") == "robot1"
    again = a.claim([("recycled", "p1")], 31, lambda item: 9.0, in_hand={"p1"})
    assert [(c.item, c.cost, c.epoch) for c in again] == [("p1", -1.0, 30)]
    assert a.owner("p1") == "robot2"
    assert a.claim([("recycled", "p1")], 32, lambda item: 9.0, in_hand={"p1"}) == []


def test_a_robot_that_picked_up_an_item_another_owned_takes_it_into_its_goal() -> None:
    """Seen in a warehouse run: robot1 picked up an item claimed by robot2 (its plan's
    committed part had the pickup), and the holding rule's boost was stripped every
    epoch as another's: the item stayed in hand until a deadline let go of it."""
    r1 = Mind(load_agent(AGENT, "robot1"))
    r1.on_claim(Claim(agent="robot2", group="recyclers", item="p1", epoch=0, cost=1.0))
    first = r1.on_percepts(seen("robot1", 0, ("p2", (1, 1))))
    assert goal(r1) == [("recycled", "p2")] and [c.item for c in first.claims] == ["p2"]
    holding = msgspec.structs.replace(seen("robot1", 1, ("p2", (1, 1))), holding=["p1"])
    out = r1.on_percepts(holding)
    assert ("recycled", "p1") in goal(r1)
    assert [(c.item, c.cost) for c in out.claims] == [("p1", -1.0)]
    assert r1.claims is not None and r1.claims.owner("p1") == "robot1"


def test_distances_on_the_30x30_campus_are_shortest_paths_and_fast() -> None:
    """The claims' distances on the biggest shipped map: breadth-first, one search per
    source cell, each later query a lookup (the issue measured 40 s and 2 GB before)."""
    import time

    from cbdi_recycling.events import Distances, map_beliefs
    from cbdi_recycling.maps import load_map

    from tests_support import grid_info

    root = Path(__file__).resolve().parents[2]
    m = load_map(root / "domains/recycling/maps/campus-30x30.toml")
    info = grid_info(m.width, m.height, sorted(m.walls), dict(m.bins), ("r",), m.name)
    base = BeliefSet.of(map_beliefs(info))
    cells = sorted(n for n, t in base.instances.items() if t == "cell")
    start, far = cells[0], cells[-1]
    beliefs = base.adding([fact("in", "r", start), fact("litter_pose", "p", far)])
    d = Distances()
    t0 = time.perf_counter()
    first = d(beliefs, "r", "p")
    again = [d(beliefs, "r", "p") for _ in range(100)]
    took = time.perf_counter() - t0
    # Manhattan distance is a lower bound on a 4-connected grid; walls make it longer.
    (x0, y0), (x1, y1) = (tuple(map(int, c.split("_")[1:])) for c in (start, far))
    assert abs(x1 - x0) + abs(y1 - y0) <= first < UNKNOWN_DISTANCE
    assert again == [first] * 100 and first == distance(beliefs, "r", "p")
    print(f"30x30: first query and 100 more in {took * 1000:.1f} ms")  # a figure, no bound


def test_an_achieved_goal_ends_every_claim_on_its_item_and_the_group_believes_it() -> None:
    a = Claims("robot1", "couriers", frozenset({"delivered"}))
    b = Claims("robot2", "couriers", frozenset({"delivered"}))
    sent = a.claim([("delivered", "p1")], 0, lambda item: 1.0)
    sent += b.claim([("delivered", "p1")], 0, lambda item: 6.0)
    for claim in sent:
        a.on_claim(claim)
        b.on_claim(claim)
    assert a.owner("p1") == b.owner("p1") == "robot1"
    done = a.release([("delivered", "p1")], achieved=True)
    assert [(c.item, c.released, c.achieved) for c in done] == [("p1", True, ["delivered", "p1"])]
    assert b.on_claim(done[0])
    # The contest is over at both: robot2's losing claim ends too, so the item, if it
    # comes back, is claimed afresh by whoever wants it then.
    assert a.owner("p1") is None and b.owner("p1") is None and b.mine() == []
    again = a.claim([("delivered", "p1")], 30, lambda item: 6.0)
    again += b.claim([("delivered", "p1")], 30, lambda item: 1.0)
    for claim in again:
        a.on_claim(claim)
        b.on_claim(claim)
    assert a.owner("p1") == b.owner("p1") == "robot2"  # nearer when the work came back


def test_a_release_says_achieved_only_for_a_goal_atom_on_its_item() -> None:
    with pytest.raises(ValueError, match="only a release"):
        Claim(agent="robot1", group="g", item="p1", achieved=["delivered", "p1"])
    with pytest.raises(ValueError, match="not a goal atom"):
        Claim(agent="robot1", group="g", item="p1", released=True, achieved=["delivered", "p2"])
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert(
            {"agent": "robot1", "group": "g", "item": "p1", "released": True, "achieved": [""]},
            Claim,
        )
    a = Claims("robot1", "g", frozenset({"delivered"}))
    other = Claim(agent="robot2", group="g", item="p1", released=True, achieved=["seen", "p1"])
    assert not a.on_claim(other)  # not a goal the group shares out: ignored


def test_a_robot_releases_a_goal_it_achieved_and_others_believe_it() -> None:
    r1 = Mind(load_agent(AGENT, "robot1"))
    r2 = Mind(load_agent(AGENT, "robot2"))
    out1 = r1.on_percepts(seen("robot1", 0, ("p1", (1, 1))))
    tell(out1, r2)
    assert r1.claims is not None and r1.claims.owner("p1") == "robot1"
    r1.beliefs = r1.beliefs.adding([fact("recycled", "p1")])  # its plan recycled p1
    out = r1.on_percepts(seen("robot1", 1))
    assert [(c.item, c.achieved) for c in out.claims] == [("p1", ["recycled", "p1"])]
    assert ("recycle", "achieved") in [(e.desire, e.event) for e in out.events]
    tell(out, r2)
    assert r2.beliefs.holds(fact("recycled", "p1"))
    # robot2 still sees p1 where it was: its rule does not take it up (achieved).
    again = r2.on_percepts(seen("robot2", 2, ("p1", (1, 1))))
    assert again.claims == [] and "recycle" not in r2.desires
    assert [e for e in again.events if e.desire == "recycle"] == []  # not even added


# -- claims that follow the work: bids, an owner's answer, handovers ---------------------
def shared_out(*views: Claims, claims: list[Claim]) -> None:
    for claim in claims:
        for view in views:
            view.on_claim(claim)


def test_a_later_robot_bids_only_when_clearly_sooner_and_again_only_when_nearer_still() -> None:
    a = Claims("robot1", "recyclers", frozenset({"recycled"}))
    b = Claims("robot2", "recyclers", frozenset({"recycled"}))
    shared_out(a, b, claims=a.claim([("recycled", "p1")], 0, lambda item: 10.0))
    assert b.owner("p1") == "robot1"
    assert b.bid(("recycled", "p1"), 5, lambda item: 0.0) == []  # the first claims' time
    # 8 is not clearly below 10 (by 3 at least): no bid, and the owner stays.
    assert b.bid(("recycled", "p1"), 20, lambda item: 8.0) == []
    bid = b.bid(("recycled", "p1"), 21, lambda item: 6.0)
    assert [(c.agent, c.item, c.epoch, c.cost, c.released) for c in bid] == [
        ("robot2", "p1", 21, 6.0, False)
    ]
    assert b.owner("p1") == "robot1"  # a bid alone moves nothing: the owner decides
    assert b.bid(("recycled", "p1"), 22, lambda item: 4.0) == []  # not 3 below its bid
    assert [c.cost for c in b.bid(("recycled", "p1"), 23, lambda item: 2.5)] == [2.5]
    assert b.bid(("recycled", "p2"), 24, lambda item: 0.0) == []  # nobody owns p2
    assert a.bid(("recycled", "p1"), 24, lambda item: 0.0) == []  # ours already
    # A robot with work of its own does not bid, however near.
    c = Claims("robot3", "recyclers", frozenset({"recycled"}))
    shared_out(c, claims=a.claim([("recycled", "p1")], 0, lambda item: 10.0))
    c.claim([("recycled", "p7")], 30, lambda item: 1.0)
    assert c.bid(("recycled", "p1"), 31, lambda item: 0.0) == []


def test_the_owner_hands_an_item_over_to_a_clearly_sooner_bidder_and_everyone_agrees() -> None:
    views = [Claims(f"robot{i}", "recyclers", frozenset({"recycled"})) for i in (1, 2, 3)]
    a, b, c = views
    shared_out(*views, claims=a.claim([("recycled", "p1")], 0, lambda item: 10.0))
    shared_out(*views, claims=c.claim([("recycled", "p1")], 30, lambda item: 9.0))  # too late
    bid = b.bid(("recycled", "p1"), 31, lambda item: 5.0)
    shared_out(*views, claims=bid)
    assert {v.owner("p1") for v in views} == {"robot1"}
    # robot1 came nearer meanwhile (cost 7 now): 5 is not clearly below 7, it declines.
    assert a.answer(bid[0], 7.0) == []
    assert {v.owner("p1") for v in views} == {"robot1"}
    # A claim of the first epochs is no bid: the contest decides, the owner hands nothing.
    early = Claim(agent="robot2", group="recyclers", item="p1", epoch=3, cost=0.0)
    assert a.answer(early, 99.0) == []
    # Later robot1 is far (cost 12): robot2's 5 is clearly sooner, the item goes to it.
    handover = a.answer(bid[0], 12.0)
    assert [(x.agent, x.to, x.released, x.epoch, x.cost) for x in handover] == [
        ("robot1", "robot2", True, 31, 5.0)
    ]
    shared_out(*views, claims=handover)
    assert {v.owner("p1") for v in views} == {"robot2"}
    assert all(set(v.held["p1"]) == {"robot2"} for v in views)  # robot3's late claim ended too
    assert a.answer(bid[0], 99.0) == []  # not ours to give any more


def test_an_owner_with_more_work_hands_over_sooner_and_never_what_it_holds() -> None:
    a = Claims("robot1", "recyclers", frozenset({"recycled"}))
    b = Claims("robot2", "recyclers", frozenset({"recycled"}))
    shared_out(a, b, claims=a.claim([("recycled", "p1"), ("recycled", "p2")], 0, lambda i: 4.0))
    # robot1 has p1 to do as well: p2 costs it 4 + LOAD_COST (5); robot2 idle at 5.
    bid = b.bid(("recycled", "p2"), 9, lambda item: 5.0)
    shared_out(a, claims=bid)
    assert a.answer(bid[0], 4.0, in_hand={"p2"}) == []  # in hand: never given
    handover = a.answer(bid[0], 4.0)
    assert [x.to for x in handover] == ["robot2"]
    shared_out(b, claims=handover)
    assert a.owner("p2") == b.owner("p2") == "robot2"
    assert a.owner("p1") == b.owner("p1") == "robot1"


def test_a_handover_is_a_release_to_another_agent() -> None:
    with pytest.raises(ValueError, match="handover"):
        Claim(agent="robot1", group="g", item="p1", to="robot2")
    with pytest.raises(ValueError, match="handover"):
        Claim(agent="robot1", group="g", item="p1", released=True, to="robot1")
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert(
            {"agent": "robot1", "group": "g", "item": "p1", "released": True, "to": "no way"},
            Claim,
        )


def test_an_item_won_but_wanted_by_no_desire_is_given_back() -> None:
    a = Claims("robot1", "recyclers", frozenset({"recycled"}))
    a.claim([("recycled", "p1"), ("recycled", "p2")], 0, lambda item: 1.0)
    out = a.unpursued({"p2", "p9"})
    assert [(c.item, c.released) for c in out] == [("p2", True)]
    assert a.owner("p2") is None and a.owner("p1") == "robot1"


def with_costs(mind: Mind, costs: dict[str, float]) -> Mind:
    mind.knowledge.cost = lambda beliefs, agent, item: costs[item]  # type: ignore[method-assign]
    return mind


def test_a_robot_that_saw_an_item_late_but_is_clearly_nearer_takes_it_over() -> None:
    """Seen in real time on paper-7x7 with three robots: whoever saw two items first
    claimed both, and the robot that came near the second later never took part."""
    r1 = with_costs(Mind(load_agent(AGENT, "robot1")), {"p1": 2.0, "p2": 6.0})
    r2 = with_costs(Mind(load_agent(AGENT, "robot2")), {"p1": 9.0, "p2": 9.0})
    tell(r1.on_percepts(seen("robot1", 0, ("p1", (1, 1)), ("p2", (1, 2)))), r2)
    assert goal(r1) == [("recycled", "p1"), ("recycled", "p2")]
    assert "recycle" not in r2.desires  # robot2 sees both far: no bid
    r2.on_percepts(seen("robot2", 10, ("p1", (1, 1)), ("p2", (1, 2))))
    assert "recycle" not in r2.desires
    # robot2 walked near p2 (cost 2 against robot1's 6 + 5 for p1): it bids.
    r2.knowledge.cost = lambda beliefs, agent, item: {"p1": 9.0, "p2": 2.0}[item]  # type: ignore[method-assign]
    bid = r2.on_percepts(seen("robot2", 11, ("p1", (1, 1)), ("p2", (1, 3))))
    assert [(c.item, c.cost) for c in bid.claims] == [("p2", 2.0)]
    answers = tell(bid, r1)
    handover = [c for a in answers for c in a.claims]
    assert [(c.item, c.to) for c in handover] == [("p2", "robot2")]
    after = r1.on_percepts(seen("robot1", 12, ("p1", (1, 1)), ("p2", (1, 2))))
    assert goal(r1) == [("recycled", "p1")]  # robot1 plans again for the rest
    starts = [c for c in after.commands if c.kind == "start_search"]
    assert starts and starts[0].reason == "goal reduced"
    tell(Reaction(claims=handover), r2)
    r2.on_percepts(seen("robot2", 12, ("p1", (1, 1)), ("p2", (1, 3))))
    assert goal(r2) == [("recycled", "p2")]
