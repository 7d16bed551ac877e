"""Beliefs go out as what changed: a receiver rebuilds every set of the series."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cbdi.beliefs import BeliefSet, BeliefsReceiver, BeliefsSender, fact, fluent, instance
from cbdi.errors import WireError
from cbdi.wire import decode, encode
from cbdi.wire.agent import BeliefsUpdate

names = st.sampled_from(["a", "b", "c", "d"])
belief = st.one_of(
    st.builds(lambda n, t: instance(n, t), names, st.sampled_from(["cell", "robot"])),
    st.builds(lambda p, a: fact(p, a), st.sampled_from(["free", "in"]), names),
    st.builds(
        lambda f, a, v: fluent(f, a, value=v), st.sampled_from(["load"]), names, st.integers(0, 3)
    ),
)
belief_sets = st.lists(st.lists(belief, max_size=8).map(BeliefSet.of), min_size=1, max_size=12)


@settings(max_examples=150, deadline=None)
@given(belief_sets, st.integers(1, 5))
def test_every_set_of_a_series_is_rebuilt_through_the_wire(
    sets: list[BeliefSet], whole_every: int
) -> None:
    sender, receiver = BeliefsSender("robot1", whole_every=whole_every), BeliefsReceiver()
    for k, beliefs in enumerate(sets):
        update = decode(encode(sender.update(beliefs, float(k), k)), BeliefsUpdate)
        assert update.seq == k + 1
        assert (update.base == 0) == (k % whole_every == 0)  # whole first and every N
        assert receiver.apply(update) == beliefs


def test_a_change_is_smaller_than_the_whole_set() -> None:
    cells = BeliefSet.of([fact("free", f"c_{i}") for i in range(500)])
    sender = BeliefsSender("robot1")
    whole = encode(sender.update(cells, 0.0, 0))
    moved = cells.removing([fact("free", "c_7")]).adding([fact("free", "c_600")])
    change = sender.update(moved, 0.5, 1)
    assert change.base == 1 and change.facts == [["free", "c_600"]]
    assert change.dropped_facts == [["free", "c_7"]]
    assert len(encode(change)) * 20 < len(whole)


def test_a_receiver_that_joins_late_waits_for_the_next_whole_set() -> None:
    sender = BeliefsSender("robot1", whole_every=64)
    sets = [BeliefSet.of([fact("in", "r", f"c_{k}")]) for k in range(4)]
    sender.update(sets[0], 0.0, 0)  # a restarted receiver missed this one
    late = BeliefsReceiver()
    assert late.apply(sender.update(sets[1], 1.0, 1)) is None
    sender.resend()  # it appeared: the scheduler sends the next set whole
    assert late.apply(sender.update(sets[2], 2.0, 2)) == sets[2]
    assert late.apply(sender.update(sets[3], 3.0, 3)) == sets[3]


@pytest.mark.parametrize(
    "fields",
    [
        {"seq": 3, "base": 3},  # a change of itself
        {"seq": 2, "base": 5},  # a change of a later update
        {"seq": 4, "base": 0, "dropped_facts": [["free", "c_1"]]},  # a whole set drops nothing
        {"seq": -1},
    ],
)
def test_nonsense_series_numbers_are_refused_on_the_wire(fields: dict[str, object]) -> None:
    import msgspec

    raw = {"schema": "cbdi.agent.BeliefsUpdate/1", "agent": "robot1", "time": 0.0}
    raw |= {"instances": {}, "facts": [], "fluents": [], **fields}
    with pytest.raises(WireError):
        decode(msgspec.msgpack.encode(raw), BeliefsUpdate)


@settings(max_examples=100, deadline=None)
@given(belief_sets, st.lists(st.tuples(st.booleans(), st.lists(belief, max_size=4)), max_size=6))
def test_a_derived_set_indexes_its_facts_as_a_fresh_one(
    sets: list[BeliefSet], changes: list[tuple[bool, list[object]]]
) -> None:
    beliefs = sets[0]
    beliefs.facts_of("free")  # built: derived sets take it over
    for adding, items in changes:
        beliefs = (beliefs.adding if adding else beliefs.removing)(items)  # type: ignore[arg-type]
        fresh = BeliefSet(beliefs.instances, beliefs.facts, beliefs.fluents)
        for name in ("free", "in", "near"):
            assert beliefs.facts_of(name) == fresh.facts_of(name)
