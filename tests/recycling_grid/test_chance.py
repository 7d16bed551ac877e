"""What the seed samples: people's phase and jitter, action-duration noise, random failures.

Each option draws from its own stream, so these tests check both what an option does and
that it leaves the rest of the run alone (litter, and the world with everything off).
"""

from __future__ import annotations

import math
import os
import random
import subprocess
import sys
from pathlib import Path

import pytest
from cbdi_recycling.chance import Chance, countdown, epochs_of, start_index, stream
from cbdi_recycling.errors import GridError as WorldError
from cbdi_recycling.maps import WorldMap, load_map, parse_map
from cbdi_recycling.world import AgentSpec, EpochResult, World
from hypothesis import given, settings
from hypothesis import strategies as st

from cbdi.wire.world import ActionRequest

MAPS = Path(__file__).resolve().parents[2] / "domains" / "recycling" / "maps"
PAPER = load_map(MAPS / "paper-7x7.toml")
WAREHOUSE = load_map(MAPS / "warehouse-15x15.toml")
EVERYTHING = Chance(people_phase=True, people_jitter=2, duration_noise=1.0, failure_probability=0.3)
_DIRS = ((1, 0), (0, 1), (-1, 0), (0, -1))


def act(agent: str, action: str, rid: str, target: tuple[int, int] | None = None) -> ActionRequest:
    return ActionRequest(agent=agent, action=action, request_id=rid, target=target)


def world(m: WorldMap, seed: int, chance: Chance | None = None, robots: int = 1) -> World:
    specs = [AgentSpec(f"r{i}", c) for i, c in enumerate(m.agent_starts[:robots])]
    return World(m, specs, seed=seed, chance=chance)


def drive(w: World, epochs: int) -> list[object]:
    """Run `w` with robots acting by a fixed rule; return every reply and epoch result.

    Idle robots pick up litter they stand on, recycle next to a bin, else move in a
    direction that depends only on the epoch and the robot: the same inputs every run.
    """
    log: list[object] = []
    for t in range(epochs):
        for i, (name, a) in enumerate(sorted(w.agents.items())):
            if a.action is not None:
                continue
            target = None
            if any(c == a.cell for c in w.litter.values()) and len(a.holding) < w.map.capacity:
                action = "pickup"
            elif a.holding and t % 3 == 0:
                action = "recycle"
            else:
                dx, dy = _DIRS[(7 * t + 3 * i) % 4]
                action, target = "move", (a.cell[0] + dx, a.cell[1] + dy)
            log.append(w.request(act(name, action, f"{name}-{t}", target)))
        log.append(w.step())
    return log


def people_cells(w: World, epochs: int) -> list[list[tuple[int, int]]]:
    cells = []
    for _ in range(epochs):
        w.step()
        cells.append([p.cell for p in w.people])
    return cells


def step_gaps(w: World, epochs: int) -> list[int]:
    """Return the epochs between consecutive steps of the first person."""
    moved, last = [], w.people[0].index
    for epoch in range(1, epochs + 1):
        w.step()
        if w.people[0].index != last:
            moved.append(epoch)
            last = w.people[0].index
    return [b - a for a, b in zip([0, *moved], moved, strict=False)]


# -- reproducibility --------------------------------------------------------------------


@pytest.mark.parametrize("m", [PAPER, WAREHOUSE], ids=["paper", "warehouse"])
def test_same_seed_same_run_over_200_epochs(m: WorldMap) -> None:
    first = drive(world(m, 7, EVERYTHING, robots=3), 200)
    assert first == drive(world(m, 7, EVERYTHING, robots=3), 200)
    assert first != drive(world(m, 8, EVERYTHING, robots=3), 200)


def test_different_seeds_start_and_walk_people_differently() -> None:
    chance = Chance(people_phase=True, people_jitter=1)
    starts = {tuple(p.index for p in world(PAPER, s, chance).people) for s in range(10)}
    assert len(starts) >= 5  # 20 x 12 phases: ten seeds almost never share one
    assert people_cells(world(PAPER, 1, chance), 200) != people_cells(world(PAPER, 2, chance), 200)
    phase_only = Chance(people_phase=True)  # the jitter's stream does not move the phase
    assert [p.index for p in world(PAPER, 1, chance).people] == [
        p.index for p in world(PAPER, 1, phase_only).people
    ]


def test_everything_off_is_the_world_of_before() -> None:
    """Phase off: people start on path[0] and step every move_step, whatever the seed."""
    for seed in range(5):
        w = world(PAPER, seed, Chance(people_phase=False, people_jitter=0))
        assert [p.cell for p in w.people] == [p.path[0] for p in PAPER.people]
        assert [p.countdown for p in w.people] == [4, 4]
        assert step_gaps(w, 200) == [4] * 50
    default = drive(world(WAREHOUSE, 3, None, robots=3), 200)
    assert default == drive(world(WAREHOUSE, 3, Chance(), robots=3), 200)


def test_streams_are_the_same_in_every_process_whatever_pythonhashseed() -> None:
    script = f"""
from cbdi.wire.world import ActionRequest
from cbdi_recycling.chance import Chance
from cbdi_recycling.maps import load_map
from cbdi_recycling.world import AgentSpec, World
m = load_map({str(MAPS / "warehouse-15x15.toml")!r})
c = Chance(people_phase=True, people_jitter=2, duration_noise=1.0, failure_probability=0.3)
w = World(m, [AgentSpec("r", m.agent_starts[0])], seed=5, chance=c)
for t in range(300):
    x, y = w.agents["r"].cell
    target = (x + (1 if t % 8 < 4 else -1), y)
    print(w.request(ActionRequest(agent="r", action="move", request_id=str(t), target=target)))
    print(w.step())
"""

    def output(hash_seed: str) -> str:
        env = {**os.environ, "PYTHONHASHSEED": hash_seed}
        run = subprocess.run(
            [sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True
        )
        return run.stdout

    first = output("1")
    assert first and first == output("4242")


# -- people -----------------------------------------------------------------------------


def test_a_phase_skips_to_the_next_free_cell_of_the_loop() -> None:
    path = ((0, 0), (1, 0), (2, 0), (3, 0))
    for seed in range(20):
        drawn = random.Random(seed).randrange(len(path))
        got = start_index(path, {path[drawn], path[(drawn + 1) % 4]}, random.Random(seed))
        assert got == (drawn + 2) % 4
    with pytest.raises(WorldError, match="no free cell"):
        start_index(path, set(path), random.Random(0))


def test_phased_people_avoid_agent_starts_other_people_and_standing_people() -> None:
    # One loop shared by two walkers, with an agent start and a person standing on it.
    text = (
        'name = "p"\ngrid = """\nB.A.\n....\n....\n"""\n'
        '[[people]]\nname = "walker1"\nmove_step = 1\npath = [[3, 0], [3, 1], [2, 1], [1, 1], '
        "[1, 0], [2, 0]]\n"
        '[[people]]\nname = "walker2"\nmove_step = 1\npath = [[1, 0], [2, 0], [3, 0], [3, 1], '
        "[2, 1], [1, 1]]\n"
        '[[people]]\nname = "stands"\nmove_step = 1\npath = [[3, 1]]\n'
    )
    m = parse_map(text)
    seen = set()
    for seed in range(40):
        w = World(m, [AgentSpec("r", (2, 0))], seed=seed, chance=Chance(people_phase=True))
        cells = [p.cell for p in w.people]
        assert len(set(cells)) == 3 and (2, 0) not in cells and cells[2] == (3, 1)
        seen.add(tuple(cells[:2]))
    assert len(seen) > 3  # the phase is sampled, not always the first free cell


def test_jitter_keeps_countdowns_at_least_one_and_moves_the_steps() -> None:
    rng = random.Random(0)
    draws = [countdown(2, 3, rng) for _ in range(2000)]
    assert min(draws) == 1 and max(draws) == 5  # 2 + [-3, 3], at least 1
    w = world(PAPER, 1, Chance(people_jitter=1))
    gaps = step_gaps(w, 400)
    assert set(gaps) == {3, 4, 5}  # the paper's people are never blocked on their loops
    assert 400 / 5 <= len(gaps) <= 400 / 3
    fast = world(PAPER, 1, Chance(people_jitter=6))
    for _ in range(200):
        fast.step()
        assert all(p.countdown >= 1 for p in fast.people)


def spawns(chance: Chance, robots: int = 0) -> list[tuple[int, str, tuple[int, int]]]:
    """Return when, what and where litter appears in 400 epochs of the warehouse, seed 3."""
    w = world(WAREHOUSE, 3, chance, robots=max(1, robots))
    out = []
    for _ in range(400):
        result = drive(w, 1)[-1] if robots else w.step()
        assert isinstance(result, EpochResult)
        out += [(result.epoch, n, w.litter[n]) for n in result.spawned]
    return out


def when(spawned: list[tuple[int, str, tuple[int, int]]]) -> list[tuple[int, str]]:
    return [(epoch, name) for epoch, name, _ in spawned]


def test_the_options_do_not_shift_the_litter_stream() -> None:
    """The litter's generator is the one it always was: a seed spawns the same items.

    The first figures were recorded with the world before any option existed. Options
    move people and robots, and litter lands on a free cell, so only the cells may differ.
    """
    before = [(185, "litter_1", (4, 13)), (231, "litter_2", (9, 14))]
    before += [(240, "litter_3", (2, 1)), (258, "litter_4", (3, 10))]
    assert spawns(Chance()) == before
    for chance in (Chance(people_phase=True, people_jitter=2), Chance(people_jitter=5)):
        assert when(spawns(chance)) == when(before)
    acting = when(spawns(Chance(), robots=3))
    assert acting and acting == when(spawns(Chance(duration_noise=2.0, failure_probability=0.5), 3))
    quiet = world(PAPER, 3, Chance(people_phase=True, people_jitter=2))
    people_cells(quiet, 100)
    assert quiet.rng.getstate() == random.Random(3).getstate()  # no spawning: never drawn


# -- actions ----------------------------------------------------------------------------


@settings(max_examples=200, deadline=None)
@given(
    st.floats(0.01, 20.0),
    st.sampled_from([0.1, 0.25, 0.5, 1.0, 3.0]),
    st.floats(0.0, 10.0),
    st.integers(0, 10**6),
)
def test_noisy_durations_are_whole_epochs_never_shorter(
    duration: float, epoch: float, noise: float, seed: int
) -> None:
    k = epochs_of(duration, epoch, noise, random.Random(seed))
    assert k >= 1 and k * epoch >= duration - 1e-6
    assert k * epoch <= duration * (1 + noise) + epoch + 1e-6


def test_noisy_actions_end_on_epoch_boundaries_and_vary() -> None:
    text = (
        'name = "n"\nepoch_duration = 0.5\ngrid = """\nBA....\n"""\n'
        "[durations]\nmove = 0.7\npickup = 3\nrecycle = 3\n"
    )
    m = parse_map(text)
    w = World(m, [AgentSpec("r", (1, 0))], chance=Chance(duration_noise=2.0))
    lasted = []
    for i in range(60):
        target = (2, 0) if w.agents["r"].cell == (1, 0) else (1, 0)  # back and forth
        reply = w.request(act("r", "move", f"m{i}", target))
        assert reply.accepted
        steps = round(reply.ends_at / 0.5)
        assert reply.ends_at == steps * 0.5  # exactly the time of that epoch
        assert reply.ends_at - reply.starts_at >= 0.7
        lasted.append(reply.ends_at - reply.starts_at)
        while True:
            result = w.step()
            if result.outcomes:
                assert result.epoch == steps and result.time == reply.ends_at
                break
    assert min(lasted) == 1.0 and max(lasted) > 1.5  # 0.7 -> 2 epochs at least, often more
    plain = World(m, [AgentSpec("r", (1, 0))])
    assert plain.request(act("r", "move", "m", (2, 0))).ends_at == 0.7  # no noise


def test_failure_probability_zero_never_fails_and_half_fails_some() -> None:
    def reasons(p: float) -> list[str]:
        w = world(WAREHOUSE, 2, Chance(failure_probability=p), robots=3)
        return [o.reason for r in drive(w, 300) if hasattr(r, "outcomes") for o in r.outcomes]

    assert not [r for r in reasons(0.0) if r.startswith("random failure")]
    assert drive(world(WAREHOUSE, 2, None, robots=3), 300) == drive(
        world(WAREHOUSE, 2, Chance(failure_probability=0.0), robots=3), 300
    )
    half = reasons(0.5)
    failed = [r for r in half if r == "random failure (p=0.5)"]
    assert 0.35 < len(failed) / len(half) < 0.65


def corridor_at_litter(p: float) -> World:
    """The corridor's robot standing on its litter, failures from now on with `p`."""
    w = World(load_map(MAPS / "corridor-6x3.toml"), [AgentSpec("r", (1, 1))])
    for cell in [(2, 1), (3, 1), (4, 1)]:
        w.request(act("r", "move", f"to{cell}", cell))
        w.step()
    w.chance = Chance(failure_probability=p)
    return w


def test_random_failures_undo_what_the_action_did_at_start() -> None:
    w = corridor_at_litter(0.999)
    assert w.request(act("r", "pickup", "p1")).accepted
    assert "plastic_4_1" not in w.litter and "plastic_4_1" in w.in_hand
    outcomes = [o for _ in range(3) for o in w.step().outcomes]
    assert [(o.status, o.reason) for o in outcomes] == [("failed", "random failure (p=0.999)")]
    assert w.litter["plastic_4_1"] == (4, 1) and not w.in_hand  # back on the ground
    assert w.agents["r"].holding == [] and w.stats("r").agents[0].failed == 1
    assert w.request(act("r", "move", "m1", (3, 1))).accepted
    assert w.step().outcomes[0].reason.startswith("random failure")
    assert w.agents["r"].cell == (4, 1)  # a failed move stays where it was
    w.chance = Chance()
    w.request(act("r", "pickup", "p2"))
    for _ in range(3):
        w.step()
    for i, cell in enumerate([(3, 1), (2, 1), (1, 1)]):
        w.request(act("r", "move", f"back{i}", cell))
        w.step()
    w.chance = Chance(failure_probability=0.999)
    assert w.request(act("r", "recycle", "r1")).accepted
    assert w.agents["r"].holding == []
    outcomes = [o for _ in range(3) for o in w.step().outcomes]
    assert outcomes[0].status == "failed" and w.agents["r"].holding == ["plastic_4_1"]
    assert w.in_hand == {"plastic_4_1"} and not w.recycled and not w.done


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10**6), st.integers(20, 120))
def test_with_every_option_on_the_world_stays_consistent(seed: int, epochs: int) -> None:
    w = world(WAREHOUSE, seed, EVERYTHING, robots=4)
    total = len(WAREHOUSE.litter)
    for _ in range(epochs):
        drive(w, 1)
        bodies = [a.cell for a in w.agents.values()] + [p.cell for p in w.people]
        assert len(bodies) == len(set(bodies))  # never two bodies in one cell
        assert not set(bodies) & (WAREHOUSE.walls | set(WAREHOUSE.bins.values()))
        assert sum(len(a.holding) for a in w.agents.values()) <= len(w.in_hand)
        assert len(w.litter) + len(w.in_hand) + len(w.recycled) == total + w.spawned
        assert all(len(a.holding) <= WAREHOUSE.capacity for a in w.agents.values())
        ends = [a.action.ends_at for a in w.agents.values() if a.action]
        assert all(math.isclose(e, round(e)) for e in ends)  # epoch_duration 1: whole


@pytest.mark.parametrize(
    ("options", "field"),
    [
        ({"people_jitter": -1}, "people_jitter"),
        ({"people_jitter": True}, "people_jitter"),
        ({"duration_noise": 10.5}, "duration_noise"),
        ({"duration_noise": math.nan}, "duration_noise"),
        ({"failure_probability": 1.0}, "failure_probability"),
        ({"failure_probability": math.inf}, "failure_probability"),
        ({"failure_probability": -0.1}, "failure_probability"),
    ],
)
def test_bad_options_are_refused_naming_the_option(options: dict[str, object], field: str) -> None:
    with pytest.raises(WorldError, match=f"^{field}: expected"):
        Chance(**options)


def test_stream_is_a_pure_function_of_seed_and_purpose() -> None:
    assert stream(3, "failures:r").random() == stream(3, "failures:r").random()
    assert stream(3, "failures:r").random() != stream(3, "durations:r").random()
    assert stream(3, "failures:r").random() != stream(4, "failures:r").random()
