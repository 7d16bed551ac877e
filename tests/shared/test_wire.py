"""Wire types: round trips, and every kind of bad payload gives a specific WireError."""

from __future__ import annotations

import contextlib
import re

import msgpack
import pytest
from cbdi_recycling.wire import Percepts
from hypothesis import given
from hypothesis import strategies as st

from cbdi.errors import WireError
from cbdi.wire import decode, decode_any, encode, schema_of
from cbdi.wire.common import ErrorReply
from cbdi.wire.world import (
    ActionRequest,
    Tick,
)


def test_round_trip_keeps_every_field() -> None:
    req = ActionRequest(agent="robot1", action="move", request_id="r-1", target=(2, 3))
    back = decode(encode(req), ActionRequest)
    assert back == req
    assert back.target == (2, 3)


def test_schema_names_carry_a_version() -> None:
    assert schema_of(ActionRequest) == "cbdi.world.ActionRequest/1"
    raw = msgpack.unpackb(
        encode(Tick(epoch=1, time=1.0, epoch_duration=1.0, speed=1, lockstep=False))
    )
    assert raw["schema"] == "cbdi.world.Tick/1"


def test_messages_are_frozen() -> None:
    req = ActionRequest(agent="a", action="pickup", request_id="1")
    with pytest.raises(AttributeError):
        req.agent = "b"  # type: ignore[misc]


def test_garbage_bytes_are_rejected_with_schema_and_key() -> None:
    with pytest.raises(WireError) as err:
        decode(b"\xc1\xff\x00garbage", ActionRequest, key="cbdi/world/rpc/act")
    assert err.value.schema == "cbdi.world.ActionRequest/1"
    assert err.value.key == "cbdi/world/rpc/act"
    assert "garbage" in err.value.reason or "msgpack" in err.value.reason


def test_wrong_field_type_names_the_field() -> None:
    payload = msgpack.packb(
        {"schema": "cbdi.world.ActionRequest/1", "agent": 7, "action": "move", "request_id": "x"}
    )
    with pytest.raises(WireError, match=r"\$\.agent"):
        decode(payload, ActionRequest)


def test_missing_field_is_named() -> None:
    payload = msgpack.packb({"schema": "cbdi.world.ActionRequest/1", "agent": "a"})
    with pytest.raises(WireError, match="missing required field"):
        decode(payload, ActionRequest)


def test_other_schema_is_rejected() -> None:
    payload = encode(ErrorReply(code="x", message="y"))
    with pytest.raises(WireError, match="wrong schema"):
        decode(payload, ActionRequest)


def test_not_a_map_is_rejected() -> None:
    with pytest.raises(WireError, match="not a message map"):
        decode(msgpack.packb([1, 2, 3]), ActionRequest)


def test_unknown_fields_are_tolerated() -> None:
    payload = msgpack.packb(
        {
            "schema": "cbdi.world.ActionRequest/1",
            "agent": "a",
            "action": "pickup",
            "request_id": "1",
            "from_the_future": 1,
        }
    )
    assert decode(payload, ActionRequest).agent == "a"


def test_decode_any_picks_by_schema() -> None:
    reply = decode_any(encode(ErrorReply(code="c", message="m")), (ActionRequest, ErrorReply))
    assert isinstance(reply, ErrorReply)
    with pytest.raises(WireError):
        decode_any(b"\x00", (ActionRequest, ErrorReply))


@given(st.binary(max_size=64))
def test_random_bytes_never_crash_the_decoder(data: bytes) -> None:
    with contextlib.suppress(WireError):  # only WireError may come out, never a crash
        decode(data, Percepts)


def test_beliefs_round_trip_through_the_wire() -> None:
    from cbdi.beliefs import BeliefSet, fact, fluent, from_wire, instance, to_wire
    from cbdi.wire.agent import BeliefsUpdate

    beliefs = BeliefSet.of(
        [instance("r", "robot"), fact("in", "r", "c_0_1"), fluent("loaded_amount", "r", value=2)]
    )
    update = decode(encode(to_wire(beliefs, "r", 3.0, epoch=3)), BeliefsUpdate)
    assert from_wire(update) == beliefs and update.epoch == 3


def _tagged(cls: type, **fields: object) -> bytes:
    return msgpack.packb({"schema": schema_of(cls), **fields})  # type: ignore[arg-type,no-any-return]


PERCEPTS = {
    "agent": "robot1",
    "epoch": 0,
    "time": 0.0,
    "position": [1, 1],
    "depth": 1,
    "free": [],
    "blocked": [],
    "litter": [],
    "holding": [],
}


@pytest.mark.parametrize(
    ("cls", "fields", "where"),
    [
        ("Check", {"atom": ["free", "c_1_1"], "op": "move"}, "`$.op`"),
        ("Check", {"atom": []}, "`$.atom`"),
        ("Check", {"atom": ["free", ""]}, "`$.atom[1]`"),
        ("Check", {"atom": ["loaded_amount", "r"], "op": "LT", "value": float("nan")}, "finite"),
        ("Percepts", {**PERCEPTS, "holding": [""]}, "`$.holding[0]`"),
        ("Percepts", {**PERCEPTS, "time": float("inf")}, "`$.time`"),
        ("Percepts", {**PERCEPTS, "agent": "robot 1"}, "`$.agent`"),
        (
            "Tick",
            {"epoch": 1, "time": 1.0, "epoch_duration": 0.0, "speed": 1.0, "lockstep": False},
            "`$.epoch_duration`",
        ),
        ("EpochAck", {"agent": "robot1/x", "epoch": 0}, "`$.agent`"),
        (
            "AgentRequest",
            {"from_agent": "r2", "group": "g", "op": "add_desire", "priority": 8},
            "`$.priority`",
        ),
        ("SearchRequest", {"agent": "r", "request_id": "s", "kind": "move"}, "`$.kind`"),
        (
            "PlanStep",
            {"step_id": "s", "action": "move", "args": [], "start": 1e400, "duration": 1},
            "finite",
        ),
    ],
)
def test_schema_valid_nonsense_is_rejected_naming_the_field(
    cls: str, fields: dict[str, object], where: str
) -> None:
    import cbdi_recycling.wire

    import cbdi.wire.agent
    import cbdi.wire.planner
    import cbdi.wire.world

    modules = (cbdi.wire.agent, cbdi.wire.planner, cbdi.wire.world, cbdi_recycling.wire)
    message = next(getattr(m, cls) for m in modules if hasattr(m, cls))
    with pytest.raises(WireError, match=re.escape(where)):
        decode(_tagged(message, **fields), message)


names = st.text(max_size=4)
atoms = st.lists(names, max_size=3)


@given(
    facts=st.lists(atoms, max_size=4),
    fluents=st.lists(st.tuples(atoms, st.floats()), max_size=3),
    instances=st.dictionaries(names, names, max_size=3),
)
def test_beliefs_that_decode_always_make_a_belief_set(
    facts: list[list[str]], fluents: list[tuple[list[str], float]], instances: dict[str, str]
) -> None:
    from cbdi.beliefs import from_wire
    from cbdi.wire.agent import BeliefsUpdate

    payload = _tagged(
        BeliefsUpdate, agent="robot1", time=0.0, instances=instances, facts=facts, fluents=fluents
    )
    try:
        update = decode(payload, BeliefsUpdate)
    except WireError:
        return
    from_wire(update)  # never a ValueError: the wire types rule out what it refuses


@pytest.mark.parametrize(
    "fields",
    [
        {"service": "", "pid": 1, "beat": 0},
        {"service": "robot1/planner", "pid": -1, "beat": 0},
        {"service": "robot1/planner", "pid": 1, "beat": "0"},
    ],
)
def test_a_heartbeat_out_of_its_bounds_is_refused(fields: dict[str, object]) -> None:
    from cbdi.wire.common import Heartbeat

    payload = msgpack.packb({"schema": schema_of(Heartbeat), **fields})
    with pytest.raises(WireError):
        decode(payload, Heartbeat)


def test_a_freeze_report_needs_finite_non_negative_times() -> None:
    from cbdi.wire.common import ServiceFrozen

    ok = ServiceFrozen(service="robot1/planner", pid=7, silent_for=1.9, limit=2.0)
    assert decode(encode(ok), ServiceFrozen) == ok
    for bad in (float("nan"), float("inf"), -1.0):
        raw = msgpack.packb({**msgpack.unpackb(encode(ok)), "silent_for": bad})
        with pytest.raises(WireError):
            decode(raw, ServiceFrozen)


def test_a_graph_view_refuses_places_off_the_map_twice_named_and_links_to_nowhere() -> None:
    """A map's places and links are checked when decoded: every place within the
    view's size, at finite coordinates, named once; a link joins two of them."""
    from cbdi.wire.world import MapLink, MapPlace, MapView

    def raw(places: list[tuple[str, float, float]], links: list[tuple[str, str]]) -> bytes:
        return msgpack.packb(
            {
                "schema": "cbdi.world.MapView/1",
                "width": 4,
                "height": 2,
                "places": [{"schema": "cbdi.world.MapPlace/1", "name": n, "at": [x, y]}
                           for n, x, y in places],
                "links": [{"schema": "cbdi.world.MapLink/1", "a": a, "b": b} for a, b in links],
            }
        )  # fmt: skip

    good = decode(raw([("shed", 0.5, 0.5), ("pond", 3.5, 1.5)], [("shed", "pond")]), MapView)
    assert good.places[1] == MapPlace(name="pond", at=(3.5, 1.5))
    assert good.links == [MapLink(a="shed", b="pond")]
    for places, links, why in [
        ([("shed", 4.5, 0.5)], [], "off the map"),
        ([("shed", float("nan"), 0.5)], [], r"\$\.places\[0\]\.at"),
        ([("shed", 0.5, 0.5), ("shed", 1.5, 0.5)], [], "appears twice"),
        ([("", 0.5, 0.5)], [], r"\$\.places\[0\]\.name"),
        ([("shed", 0.5, 0.5)], [("shed", "pond")], "does not join two places"),
        ([("shed", 0.5, 0.5)], [("shed", "shed")], "does not join two places"),
    ]:
        with pytest.raises(WireError, match=why):
            decode(raw(places, links), MapView)
    with pytest.raises(ValueError, match="off the map"):
        MapView(width=1, height=1, places=[MapPlace(name="far", at=(2.0, 0.5))])
