"""The world's state file (`cbdi_world.recovery`): what a restarted world goes on from.

A simulator saved at an epoch and read back steps exactly as the one that went on
(the same litter, people, bodies, random draws and pending actions), after the requests
noted since the save are served again; a file that is missing, damaged or of another
world is refused by name, and the host then starts afresh with a warning.
"""

from __future__ import annotations

import io
import pickle
import random
from pathlib import Path

import pytest

from cbdi.runtime.log import Log
from cbdi.simulator import EpochResult, Simulator, SimulatorConfig, load_simulator
from cbdi.wire.world import ActionReply, ActionRequest
from cbdi_world.recovery import (
    MAGIC,
    Keeper,
    Published,
    Served,
    StateFile,
    StateFileError,
    Stepped,
    WorldState,
    restored_simulator,
    simulator_state,
)
from cbdi_world.trace import RequestTrace
from tests_support import REPO

MAPS = REPO / "domains/recycling/maps"
AGENTS = ("robot1", "robot2")
# Everything the seed samples, so the generators' states matter after a restore.
OPTIONS = {
    "people_phase": True,
    "people_jitter": 1,
    "duration_noise": 0.5,
    "failure_probability": 0.2,
    "spawn": 0.3,
}


def grid(map_name: str = "paper-7x7.toml", seed: int = 5) -> Simulator:
    config = SimulatorConfig(
        map=str(MAPS / map_name), agents=AGENTS, seed=seed, options=dict(OPTIONS)
    )
    return load_simulator("recycling")(config)


def requests_for(world: Simulator, rng: random.Random, epoch: int) -> list[ActionRequest]:
    """A wandering robot's primitive actions: pick up what it stands on, else step."""
    out = []
    for view in world.stats().agents:
        name = view.agent
        cell = world.agents[name].cell  # type: ignore[attr-defined]
        here = [n for n, c in world.litter.items() if c == cell]  # type: ignore[attr-defined]
        rid = f"{name}-{epoch}"
        if here:
            out.append(ActionRequest(agent=name, action="pickup", request_id=rid, item=here[0]))
        else:
            dx, dy = rng.choice([(1, 0), (-1, 0), (0, 1), (0, -1)])
            target = (cell[0] + dx, cell[1] + dy)
            out.append(ActionRequest(agent=name, action="move", request_id=rid, target=target))
    return out


def play(
    world: Simulator, rng: random.Random, epochs: int
) -> list[tuple[EpochResult, list[ActionReply]]]:
    """Step `epochs` epochs, each after serving the wanderers' requests."""
    seen = []
    for _ in range(epochs):
        replies = [world.request(r) for r in requests_for(world, rng, world.epoch)]
        seen.append((world.step(), replies))
    return seen


@pytest.mark.parametrize("map_name", ["paper-7x7.toml", "campus-30x30.toml"])
def test_a_restored_world_steps_as_the_one_that_went_on(tmp_path: Path, map_name: str) -> None:
    world, rng = grid(map_name), random.Random(11)
    play(world, rng, 12)
    store = StateFile(tmp_path / "world.state")
    result = world.step()
    state = WorldState(simulator_state(world), result, RequestTrace())
    store.save(state)
    store.note(Published(result.epoch))
    # Requests served after the save: noted, then served again on the restored world.
    served = [(r, world.request(r)) for r in requests_for(world, rng, world.epoch)]
    for r, reply in served:
        store.note(Served(world.epoch, r, reply))
    store.close()

    back = store.load()
    assert back.state.result == result and back.entries[0] == Published(result.epoch)
    restored = restored_simulator(grid(map_name), back.state.simulator, store.path)
    assert restored is not world and restored.epoch == world.epoch
    again_served = [restored.request(e.request) for e in back.entries if isinstance(e, Served)]
    assert again_served == [reply for _, reply in served]
    rng_copy = random.Random()
    rng_copy.setstate(rng.getstate())
    went_on, again = play(world, rng, 40), play(restored, rng_copy, 40)
    assert again == went_on  # outcomes, percepts, snapshots (poses) and replies
    assert restored.stats() == world.stats()  # contacts, failures, spawned litter too


def test_the_clock_and_courier_simulators_round_trip(tmp_path: Path) -> None:
    courier_map = REPO / "domains/courier/maps"
    maps = sorted(courier_map.glob("*.toml"))
    cases = [("clock", "", {}), ("courier", str(maps[0]) if maps else "", {})]
    for name, map_file, options in cases:
        config = SimulatorConfig(map=map_file, agents=("robot1",), seed=3, options=options)
        world = load_simulator(name)(config)
        for _ in range(5):
            world.step()
        restored = restored_simulator(load_simulator(name)(config), simulator_state(world))
        assert [restored.step() for _ in range(5)] == [world.step() for _ in range(5)]


def test_a_simulator_may_save_its_own_state() -> None:
    class Counter:
        def __init__(self) -> None:
            self.n = 0

        def save_state(self) -> bytes:
            return str(self.n).encode()

        def restore_state(self, data: bytes) -> None:
            self.n = int(data)

    c = Counter()
    c.n = 41
    fresh = Counter()
    assert restored_simulator(fresh, simulator_state(c)) is fresh  # type: ignore[arg-type]
    assert fresh.n == 41


def test_the_trace_goes_on_after_a_round_trip() -> None:
    trace, other = RequestTrace(), RequestTrace()
    req = ActionRequest(agent="robot1", action="move", request_id="r-1", target=(1, 2))
    reply = ActionReply(request_id="r-1", accepted=True)
    for t in (trace, other):
        t.record(0, req, reply)
        t.record(1, req, reply)
    trace = pickle.loads(pickle.dumps(trace))
    for t in (trace, other):
        t.record(2, req, reply)
    assert trace.digest() == other.digest() and trace.count == other.count == 3
    assert RequestTrace().digest() != trace.digest()


def _saved(path: Path, world: Simulator) -> StateFile:
    store = StateFile(path)
    store.save(WorldState(simulator_state(world), world.initial(), RequestTrace()))
    store.close()
    return store


@pytest.mark.parametrize(
    ("damage", "says"),
    [
        (lambda p: p.unlink(), "No such file"),
        (lambda p: p.write_bytes(b"\x00garbage" * 50), "not a cbdi world state"),
        (lambda p: p.write_bytes(MAGIC + b"\x10\x00\x00\x00junk"), "no whole state"),
        (lambda p: p.write_bytes(p.read_bytes()[:-40]), "no whole state"),  # torn
        (lambda p: p.write_bytes(p.read_bytes()[:300] + b"x" + p.read_bytes()[301:]), "no whole"),
    ],
)
def test_a_bad_state_file_is_refused_by_name(tmp_path: Path, damage: object, says: str) -> None:
    path = tmp_path / "world.state"
    _saved(path, grid())
    damage(path)  # type: ignore[operator]
    with pytest.raises(StateFileError, match=says) as caught:
        StateFile(path).load()
    assert str(path) in str(caught.value)


def test_the_host_starts_afresh_on_a_bad_or_foreign_file_with_a_warning(tmp_path: Path) -> None:
    out = io.StringIO()
    path = tmp_path / "world.state"
    path.write_bytes(b"not a state")
    assert Keeper(path, Log("world", stream=out)).recover(grid()) is None
    _saved(path, grid("warehouse-15x15.toml"))  # another map
    assert Keeper(path, Log("world", stream=out)).recover(grid()) is None
    lines = out.getvalue().splitlines()
    assert len(lines) == 2 and all("event=state_unusable" in line for line in lines)
    assert all(str(path) in line and "then=afresh" in line for line in lines)
    assert "not a cbdi world state" in lines[0] and "of another world" in lines[1]


def test_a_torn_tail_is_cut_and_noting_goes_on(tmp_path: Path) -> None:
    path = tmp_path / "world.state"
    world = grid()
    store = _saved(path, world)
    req = ActionRequest(agent="robot1", action="move", request_id="robot1-1", target=(0, 0))
    reply = ActionReply(request_id="robot1-1", accepted=False, reason="no")
    store = StateFile(path)
    with path.open("ab") as f:
        f.write(b"\x99\x00\x00\x00\x01\x02")  # half a record: a write cut short
    assert store.load().entries == []
    store.open_log()
    store.note(Served(0, req, reply))
    store.note(Stepped(1, {"robot1/executor": (0, 2)}))
    store.note(Published(1))
    store.close()
    again = StateFile(path).load()
    assert again.entries == [
        Served(0, req, reply),
        Stepped(1, {"robot1/executor": (0, 2)}),
        Published(1),
    ]


def test_a_state_file_that_cannot_be_written_is_given_up(tmp_path: Path) -> None:
    out = io.StringIO()
    keeper = Keeper(tmp_path / "gone" / "world.state", Log("world", stream=out))
    world = grid()
    keeper.save(WorldState(simulator_state(world), world.initial(), RequestTrace()))
    keeper.note(Published(0))  # given up: nothing more, no second warning
    assert keeper.file is None
    assert out.getvalue().count("event=state_not_saved") == 1
