"""The world core: action rules, people, sensing, spawning, physics and determinism."""

from __future__ import annotations

from pathlib import Path

import pytest
from cbdi_recycling.errors import GridError as WorldError
from cbdi_recycling.errors import MapError, UnknownAgentError
from cbdi_recycling.maps import load_map, parse_map
from cbdi_recycling.world import AgentSpec, World
from hypothesis import given, settings
from hypothesis import strategies as st

from cbdi.wire.world import ActionRequest

MAPS = Path(__file__).resolve().parents[2] / "domains" / "recycling" / "maps"


def req(
    agent: str, action: str, target: tuple[int, int] | None = None, item: str | None = None
) -> ActionRequest:
    return ActionRequest(
        agent=agent, action=action, request_id=f"{agent}-{action}", target=target, item=item
    )


def corridor() -> World:
    return World(load_map(MAPS / "corridor-6x3.toml"), [AgentSpec("r", (1, 1))])


def run(world: World, epochs: int) -> list[str]:
    seen = []
    for _ in range(epochs):
        seen += [f"{o.action}:{o.status}:{o.reason}" for o in world.step().outcomes]
    return seen


def test_move_takes_one_epoch_and_counts() -> None:
    w = corridor()
    reply = w.request(req("r", "move", (2, 1)))
    assert reply.accepted and (reply.starts_at, reply.ends_at) == (0.0, 1.0)
    assert w.agents["r"].cell == (1, 1)  # logically still in the source until completion
    assert run(w, 1) == ["move:succeeded:"]
    assert w.agents["r"].cell == (2, 1) and w.stats("r").agents[0].counts["moves"] == 1


@pytest.mark.parametrize(
    ("request_", "reason"),
    [
        (req("r", "fly"), "unknown action"),
        (req("r", "move"), "needs a target"),
        (req("r", "move", (3, 1)), "not next to"),
        (req("r", "move", (1, -1)), "outside the map"),
        (req("r", "pickup"), "no litter in cell"),
        (req("r", "recycle"), "holding nothing"),
    ],
)
def test_rejections_are_immediate_and_counted(request_: ActionRequest, reason: str) -> None:
    w = corridor()
    reply = w.request(request_)
    assert not reply.accepted and reason in reply.reason
    assert w.stats("r").agents[0].rejected == 1


def test_one_action_at_a_time() -> None:
    w = corridor()
    assert w.request(req("r", "move", (2, 1))).accepted
    busy = w.request(req("r", "move", (2, 1)))
    assert not busy.accepted and "busy with move" in busy.reason


@pytest.mark.parametrize(("target", "reason"), [((1, 0), "wall"), ((0, 1), "bin")])
def test_moves_into_walls_and_bins_fail_at_completion(target: tuple[int, int], reason: str) -> None:
    w = corridor()
    assert w.request(req("r", "move", target)).accepted
    assert run(w, 1) == [f"move:failed:{reason}"]
    assert w.agents["r"].cell == (1, 1) and w.stats("r").agents[0].failed == 1


def test_pickup_and_recycle_follow_the_domain() -> None:
    w = corridor()
    for cell in [(2, 1), (3, 1), (4, 1)]:
        w.request(req("r", "move", cell))
        run(w, 1)
    assert w.request(req("r", "pickup")).accepted
    assert "plastic_4_1" not in w.litter  # at start: gone from the cell
    assert run(w, 2) == [] and w.agents["r"].holding == []
    assert run(w, 1) == ["pickup:succeeded:"] and w.agents["r"].holding == ["plastic_4_1"]
    assert not w.done
    far = w.request(req("r", "recycle"))
    assert not far.accepted and "no bin next to" in far.reason
    for cell in [(3, 1), (2, 1), (1, 1)]:
        w.request(req("r", "move", cell))
        run(w, 1)
    assert w.request(req("r", "recycle")).accepted
    assert w.agents["r"].holding == [] and not w.done  # in the bin only at the end
    assert run(w, 3) == ["recycle:succeeded:"]
    assert w.done and w.recycled == ["plastic_4_1"]
    s = w.stats().agents[0]
    assert (s.counts["moves"], s.counts["pickups"], s.counts["recycled"]) == (6, 1, 1)


def test_capacity_is_enforced() -> None:
    text = 'name = "c"\ngrid = """\nBALLLL\n"""\n[agents]\ncapacity = 2\n'
    w = World(parse_map(text), [AgentSpec("r", (1, 0))])
    for cell in [(2, 0), (3, 0)]:
        w.request(req("r", "move", cell))
        run(w, 1)
        assert w.request(req("r", "pickup")).accepted
        run(w, 3)
    w.request(req("r", "move", (4, 0)))
    run(w, 1)
    full = w.request(req("r", "pickup"))
    assert not full.accepted and "capacity" in full.reason


def test_two_agents_into_one_cell_first_by_name_wins() -> None:
    w2 = World(
        parse_map('name = "x"\ngrid = """\nBA.A\n"""\n'),
        [AgentSpec("zed", (1, 0)), AgentSpec("amy", (3, 0))],
    )
    w2.request(req("zed", "move", (2, 0)))
    w2.request(req("amy", "move", (2, 0)))
    outcomes = {o.agent: o for o in w2.step().outcomes}
    assert outcomes["amy"].status == "succeeded"
    assert outcomes["zed"].reason == "blocked by agent amy"
    assert w2.stats("zed").agents[0].counts["blocked"] == 1


def test_people_walk_their_loop_every_move_step_and_wait_when_blocked() -> None:
    text = (
        'name = "p"\ngrid = """\nBA...\n.....\n"""\n'
        '[[people]]\nname = "p"\nmove_step = 2\npath = [[2, 0], [3, 0], [3, 1], [2, 1]]\n'
    )
    w = World(parse_map(text), [AgentSpec("r", (1, 0))])
    cells = []
    for _ in range(8):
        w.step()
        cells.append(w.people[0].cell)
    assert cells == [(2, 0), (3, 0), (3, 0), (3, 1), (3, 1), (2, 1), (2, 1), (2, 0)]
    w2 = World(parse_map(text), [AgentSpec("r", (1, 0))])
    w2.request(req("r", "move", (1, 1)))
    w2.step()
    w2.request(req("r", "move", (2, 1)))  # park on the person's path
    w2.step()
    for _ in range(8):
        w2.step()
    assert w2.people[0].cell == (3, 1)  # waits in front of the robot, never walks through it
    w2.request(req("r", "move", (1, 1)))
    for _ in range(2):
        w2.step()
    assert w2.people[0].cell == (2, 1)


def test_a_person_blocked_for_its_patience_turns_round() -> None:
    text = (
        'name = "p"\ngrid = """\nB....\n.....\nA....\n"""\n'
        '[[people]]\nname = "p"\nmove_step = 1\npatience = 3\n'
        "path = [[1, 1], [2, 1], [3, 1], [3, 2], [2, 2], [1, 2]]\n"
    )
    w = World(parse_map(text), [AgentSpec("r", (0, 2))])
    w.request(req("r", "move", (1, 2)))  # stand where the person's loop ends
    cells = []
    for _ in range(10):
        w.step()
        cells.append(w.people[0].cell)
    # (2, 2) is reached after 4 epochs; blocked by the robot on (1, 2) for 3 epochs, the
    # person walks back the way it came.
    assert cells[:5] == [(2, 1), (3, 1), (3, 2), (2, 2), (2, 2)]
    assert cells[6:9] == [(2, 2), (3, 2), (3, 1)]
    assert w.people[0].cell != (1, 2) and w.agents["r"].cell == (1, 2)
    forever = parse_map(text.replace("patience = 3", "patience = 0"))
    assert forever.people[0].patience == 0
    with pytest.raises(MapError, match=r"people\[0\]\.patience"):
        parse_map(text.replace("patience = 3", "patience = -1"))


def test_a_person_blocks_a_move() -> None:
    text = (
        'name = "p"\ngrid = """\nBA.\n...\n"""\n'
        '[[people]]\nname = "walker"\nmove_step = 50\npath = [[2, 0], [2, 1]]\n'
    )
    w = World(parse_map(text), [AgentSpec("r", (1, 0))])
    w.request(req("r", "move", (2, 0)))
    assert run(w, 1) == ["move:failed:blocked by person walker"]


def test_sensing_square_is_clipped_and_sees_litter_and_others() -> None:
    w = World(load_map(MAPS / "paper-7x7.toml"), [AgentSpec("r", (0, 1), detection_depth=1)])
    p = w.percepts("r")
    square = set(map(tuple, p.free)) | set(map(tuple, p.blocked))
    assert square == {(0, 0), (1, 0), (1, 1), (0, 2), (1, 2)}  # clipped at the border
    assert (0, 0) in map(tuple, p.blocked)  # the bin
    wide = World(load_map(MAPS / "paper-7x7.toml"), [AgentSpec("r", (3, 2), detection_depth=2)])
    seen = wide.percepts("r")
    assert (4, 1) in map(tuple, seen.blocked) and len(seen.free) + len(seen.blocked) == 24
    assert {
        i.name
        for i in World(
            load_map(MAPS / "paper-7x7.toml"), [AgentSpec("r", (3, 2), detection_depth=4)]
        )
        .percepts("r")
        .items
    } == {"plastic_6_1", "plastic_4_6", "plastic_3_6"}


def test_unknown_agent_and_bad_placement() -> None:
    w = corridor()
    with pytest.raises(UnknownAgentError):
        w.request(req("ghost", "move", (2, 1)))
    with pytest.raises(UnknownAgentError):
        w.stats("ghost")
    with pytest.raises(WorldError, match="cannot start"):
        World(load_map(MAPS / "corridor-6x3.toml"), [AgentSpec("r", (0, 0))])


def test_spawning_is_seeded() -> None:
    m = load_map(MAPS / "warehouse-15x15.toml")

    def litter(seed: int) -> dict[str, tuple[int, int]]:
        w = World(m, [AgentSpec("r", m.agent_starts[0])], seed=seed)
        for _ in range(400):
            w.step()
        return dict(w.litter)

    first = litter(3)
    assert first == litter(3) and first != litter(4)
    assert any(n.startswith("litter_") for n in first)


def test_bodies_glide_to_cell_centres_and_contacts_are_counted() -> None:
    text = (
        'name = "p"\ngrid = """\nBA.\n...\n"""\n'
        '[[people]]\nname = "walker"\nmove_step = 1\npath = [[1, 1], [1, 0]]\n'
    )
    w = World(parse_map(text), [AgentSpec("r", (1, 0))])
    assert w.snapshot().agents[0].pose == (1.5, 0.5)
    w.request(req("r", "move", (2, 0)))
    w.step()  # the robot leaves (1,0) for (2,0) as the walker steps into (1,0) behind it
    snap = w.snapshot()
    assert snap.agents[0].pose == (2.5, 0.5) and snap.people[0].pose == (1.5, 0.5)
    assert w.stats("r").agents[0].counts["contacts"] >= 1


def _replay(seed: int, script: list[tuple[str, str, tuple[int, int] | None]]) -> list[object]:
    m = load_map(MAPS / "warehouse-15x15.toml")
    w = World(m, [AgentSpec(f"r{i}", c) for i, c in enumerate(m.agent_starts[:4])], seed=seed)
    log: list[object] = []
    for agent, action, target in script:
        log.append(w.request(req(agent, action, target)).accepted)
        log.append(w.step())
    return log


@settings(max_examples=25, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["r0", "r1", "r2", "r3"]),
            st.sampled_from(["move", "pickup", "recycle"]),
            st.sampled_from([(0, 1), (1, 0), (0, -1), (-1, 0)]),
        ),
        max_size=60,
    ),
    st.integers(0, 5),
)
def test_random_runs_keep_the_world_consistent(moves: list, seed: int) -> None:
    m = load_map(MAPS / "warehouse-15x15.toml")
    w = World(m, [AgentSpec(f"r{i}", c) for i, c in enumerate(m.agent_starts[:4])], seed=seed)
    total = len(m.litter)
    for agent, action, (dx, dy) in moves:
        x, y = w.agents[agent].cell
        w.request(req(agent, action, (x + dx, y + dy) if action == "move" else None))
        w.step()
        bodies = [a.cell for a in w.agents.values()] + [p.cell for p in w.people]
        assert len(bodies) == len(set(bodies))  # never two bodies in one cell
        assert not set(bodies) & (m.walls | set(m.bins.values()))
        held = sum(len(a.holding) for a in w.agents.values())
        assert held <= len(w.in_hand)
        assert len(w.litter) + len(w.in_hand) + len(w.recycled) == total + w.spawned
        assert all(len(a.holding) <= m.capacity for a in w.agents.values())
    script = [(a, act, None if act != "move" else w.agents[a].cell) for a, act, _ in moves[:10]]
    assert _replay(seed, script) == _replay(seed, script)  # same inputs, same run
