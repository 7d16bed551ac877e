"""The courier domain's simulator: its physics (battery, doors, the cart), what robots
sense, and the world service hosting it on the in-memory bus with a manual clock."""

from __future__ import annotations

from pathlib import Path

import pytest
from cbdi_courier.floor import load_floor
from cbdi_courier.simulator import CourierSimulator
from test_bad_input import alone

from cbdi import keys
from cbdi.bus import request
from cbdi.clock import ManualClock
from cbdi.errors import ConfigError, RequestFailedError
from cbdi.runtime.together import TogetherService
from cbdi.simulator import EpochResult, SimulatorConfig
from cbdi.wire.world import ActionReply, ActionRequest, Sensed, WorldInfo, WorldInfoRequest
from cbdi_world.service import WorldSettings, build_world, world_main
from tests_support import REPO

MAP = REPO / "domains/courier/maps/office-11x7.toml"


def sim(tmp_path: Path, **changes: str) -> CourierSimulator:
    text = MAP.read_text(encoding="utf-8")
    for old, new in changes.items():
        text = text.replace(old, new)
    path = tmp_path / "office.toml"
    path.write_text(text, encoding="utf-8")
    return CourierSimulator(SimulatorConfig(map=str(path), agents=("robot1",), seed=1))


def drive(s: CourierSimulator, src: str, dst: str, n: int = 1) -> ActionReply:
    req = ActionRequest(
        agent="robot1", action="drive", request_id=f"d{n}", args=["robot1", src, dst]
    )
    return s.request(req)


def sensed(s: CourierSimulator) -> Sensed:
    result = s.step()
    (p,) = [p for p in result.percepts if isinstance(p, Sensed) and p.agent == "robot1"]
    return p


def test_a_drive_uses_charge_and_a_robot_senses_where_it_is(tmp_path: Path) -> None:
    """Mid-drive a robot senses its state as it is, not as the drive will leave it:
    still at the cell it left, busy, the charge used; both cells taken. Where the drive
    leaves it is the planner's to work out (tests/planner/test_running_steps.py)."""
    s = sim(tmp_path)
    reply = drive(s, "c_1_4", "c_2_4")
    assert reply.accepted and reply.ends_at == 2.0
    mid = sensed(s)
    assert ["at", "robot1", "c_1_4"] in mid.add and ["at", "robot1", "c_2_4"] in mid.delete
    assert ["idle", "robot1"] in mid.delete
    assert mid.fluents == [(["battery", "robot1"], 19.0)]
    assert ["clear", "c_1_4"] in mid.delete and ["clear", "c_2_4"] in mid.delete
    end = s.step()
    assert [o.status for o in end.outcomes] == ["succeeded"]
    arrived = next(p for p in end.percepts if isinstance(p, Sensed) and p.agent == "robot1")
    assert ["at", "robot1", "c_2_4"] in arrived.add and ["idle", "robot1"] in arrived.add
    assert ["clear", "c_1_4"] in arrived.add
    busy = drive(s, "c_2_4", "c_9_9", 2)
    assert not busy.accepted and "not a floor cell" in busy.reason


def test_an_empty_battery_refuses_a_drive_and_a_dock_fills_it(tmp_path: Path) -> None:
    s = sim(tmp_path, **{"battery = 20": "battery = 1"})
    assert drive(s, "c_1_4", "c_2_4").accepted
    s.step(), s.step()
    empty = drive(s, "c_2_4", "c_3_4", 2)
    assert not empty.accepted and "battery is empty" in empty.reason


def test_a_door_that_closes_during_a_drive_fails_it(tmp_path: Path) -> None:
    s = sim(tmp_path, **{"door_close_probability = 0.04": "door_close_probability = 1.0"})
    s.robots["robot1"].cell = (5, 2)
    s.open[(4, 2)] = True
    assert drive(s, "c_5_2", "c_4_2").accepted
    result = s.step()  # the door closes on the first epoch: the drive is broken
    result = s.step()
    (outcome,) = result.outcomes
    assert outcome.status == "failed" and "door at c_4_2 closed" in outcome.reason
    assert s.robots["robot1"].cell == (5, 2)


@pytest.mark.parametrize("first", ["robot1", "robot2"])
def test_two_drives_into_one_cell_in_one_epoch_go_by_name_not_by_arrival(
    tmp_path: Path, first: str
) -> None:
    """In lockstep the requests of an epoch come in any order: they must not decide each
    other. Both are accepted; at the epoch's end the first robot by name takes the cell
    and the other's drive fails at once, its charge given back."""
    text = MAP.read_text(encoding="utf-8")
    path = tmp_path / "office.toml"
    path.write_text(text, encoding="utf-8")
    s = CourierSimulator(SimulatorConfig(map=str(path), agents=("robot1", "robot2"), seed=1))
    s.robots["robot1"].cell, s.robots["robot2"].cell = (1, 4), (3, 4)
    src = {"robot1": "c_1_4", "robot2": "c_3_4"}
    order = [first, *(r for r in ("robot1", "robot2") if r != first)]
    for n, robot in enumerate(order):
        req = ActionRequest(
            agent=robot,
            action="drive",
            request_id=f"{robot}-{n}",
            args=[robot, src[robot], "c_2_4"],
        )
        assert s.request(req).accepted
    result = s.step()
    (lost,) = result.outcomes
    assert (lost.agent, lost.status) == ("robot2", "failed")
    assert "c_2_4 is not clear (robot1 drives there)" in lost.reason
    assert s.robots["robot2"].battery == 20 and s.robots["robot2"].cell == (3, 4)
    assert s.robots["robot2"].action is None
    assert [o.agent for o in s.step().outcomes] == ["robot1"]
    assert s.robots["robot1"].cell == (2, 4)


def test_an_unknown_action_is_refused_naming_the_courier_actions(tmp_path: Path) -> None:
    s = sim(tmp_path)
    req = ActionRequest(agent="robot1", action="move", request_id="m", args=["robot1", "c_1_4"])
    reply = s.request(req)
    assert not reply.accepted and "drive" in reply.reason and "charge" in reply.reason


ROUNDS = REPO / "domains/courier/maps/rounds-10x4.toml"


def act(s: CourierSimulator, name: str, *args: str) -> None:
    req = ActionRequest(agent="robot1", action=name, request_id=name, args=["robot1", *args])
    assert s.request(req).accepted


def of(agent: str, result: EpochResult) -> Sensed:
    return next(p for p in result.percepts if isinstance(p, Sensed) and p.agent == agent)


def test_a_parcel_of_two_rounds_comes_back_and_every_robot_is_told(tmp_path: Path) -> None:
    text = ROUNDS.read_text(encoding="utf-8").replace("to = [7, 2]", "to = [1, 2]")
    path = tmp_path / "rounds.toml"
    path.write_text(text, encoding="utf-8")
    s = CourierSimulator(SimulatorConfig(map=str(path), agents=("robot1", "robot2"), seed=1))
    far = of("robot2", s.step())
    assert ["parcel_at", "p1", "c_2_1"] in far.add  # an order, out of robot2's sight
    act(s, "drive", "c_1_1", "c_2_1")
    s.step(), s.step()
    act(s, "grab", "p1", "c_2_1")
    s.step()
    act(s, "drive", "c_2_1", "c_1_1")
    s.step(), s.step()
    act(s, "drive", "c_1_1", "c_1_2")
    s.step(), s.step()
    act(s, "drop", "p1", "c_1_2")
    result = s.step()
    assert s.delivered == ["p1"] and "p1" not in s.parcels and not s.done
    seen = of("robot2", result)
    assert ["delivered", "p1"] in seen.add
    for _ in range(3):  # again_after = 3 s: back at its start, undelivered
        result = s.step()
    assert s.parcels["p1"] == (2, 1)
    seen = of("robot2", result)
    assert ["delivered", "p1"] in seen.delete and ["parcel_at", "p1", "c_2_1"] in seen.add
    assert s.stats().totals == {"parcels": 2, "deliveries": 4, "delivered": 1}


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("rounds = 2\nagain_after = 3.0\n\n[[parcels]]", "rounds = 1.5\n\n[[parcels]]", "rounds"),
        ("rounds = 2\nagain_after = 3.0\n\n[[parcels]]", "rounds = 0\n\n[[parcels]]", "rounds"),
        ("again_after = 3.0\n\n[[parcels]]", "again_after = -1\n\n[[parcels]]", "again_after"),
        ("again_after = 3.0\n\n[[parcels]]", 'again_after = "soon"\n\n[[parcels]]', "again_after"),
    ],
)
def test_a_bad_round_is_refused_naming_the_parcel(
    tmp_path: Path, old: str, new: str, field: str
) -> None:
    text = ROUNDS.read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "rounds.toml"
    path.write_text(text.replace(old, new), encoding="utf-8")
    with pytest.raises(ConfigError, match=rf"parcels\[0\]\.{field}"):
        load_floor(path)


async def test_the_world_service_hosts_the_courier_simulator() -> None:
    settings = WorldSettings(
        map=str(MAP), agent=("robot1", "robot2"), wait_agents=0, simulator="courier"
    )
    shell = TogetherService("world", settings, world_main(build_world(settings), ManualClock()))
    async with alone(shell) as (bus, _ctx):
        info = await request(bus, keys.world_rpc("info"), WorldInfoRequest(), WorldInfo)
        assert info.simulator == "courier"
        assert ["dock", "c_5_5"] in info.facts and info.instances["p1"] == "parcel"
        act = keys.world_rpc("act")
        go = ActionRequest(
            agent="robot1", action="drive", request_id="r1", args=["robot1", "c_1_4", "c_1_5"]
        )
        assert (await request(bus, act, go, ActionReply)).accepted
        stranger = ActionRequest(
            agent="robot9", action="drive", request_id="r2", args=["robot9", "c_3_4", "c_3_5"]
        )
        with pytest.raises(RequestFailedError, match="unknown agent 'robot9'"):
            await request(bus, act, stranger, ActionReply)
