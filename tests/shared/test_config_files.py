"""Map, scenario and agent files: every mistake names the file and the field (issue 15).

Not UTF-8, a wrong type, a value out of range, a rule over a predicate the domain
lacks: each is a `CbdiError` saying where, never a traceback; a fuzz of the shipped
files gives nothing else, and `cbdi up` exits 2 for a bad scenario.
"""

from __future__ import annotations

import dataclasses
import os
import random
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from cbdi_recycling.maps import load_map

from cbdi.errors import CbdiError
from cbdi.launcher.scenario import load_scenario
from cbdi.launcher.services import plan_services, world_args
from cbdi_scheduler.agentfile import load_agent

REPO = Path(__file__).resolve().parents[2]
MAP = REPO / "domains/recycling/maps/paper-7x7.toml"
SCENARIO = REPO / "domains/recycling/scenarios/paper-7x7.toml"
AGENT = REPO / "domains/recycling/agents/recycler.toml"
DOMAIN = REPO / "domains/recycling/pddl/domain.pddl"
CBDI = Path(sys.executable).parent / "cbdi"


def scenario(tmp_path: Path, run: str) -> Path:
    path = tmp_path / "s.toml"
    head = f'name = "s"\nmap = "{MAP}"\n[run]\nsimulator = "recycling"\n'
    path.write_text(f'{head}{run}\n[[agents]]\nname = "robot1"\n')
    return path


def agent(tmp_path: Path, old: str, new: str) -> Path:
    text = AGENT.read_text().replace('domain = "../pddl/domain.pddl"', f'domain = "{DOMAIN}"')
    assert old in text
    path = tmp_path / "agent.toml"
    path.write_text(text.replace(old, new, 1))
    return path


LOADERS: dict[str, tuple[Path, Callable[[Path], object]]] = {
    "map": (MAP, load_map),
    "scenario": (SCENARIO, load_scenario),
    "agent": (AGENT, lambda p: load_agent(p, "robot1")),
}


@pytest.mark.parametrize("kind", sorted(LOADERS))
def test_a_file_that_is_not_utf8_is_named(kind: str, tmp_path: Path) -> None:
    original, load = LOADERS[kind]
    path = tmp_path / original.name
    path.write_bytes(b'name = "\xff\xfe"\n' + original.read_bytes())
    with pytest.raises(CbdiError, match=r"not UTF-8 text \(byte 8\)") as err:
        load(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize(
    ("run", "field"),
    [
        ("until = []", "run.until"),
        ("until = -1", "run.until"),
        ('until = "nan"', "run.until"),
        ("max_time = -5", "run.max_time"),
        ("max_time = inf", "run.max_time"),
        ("speed = nan", "run.speed"),
        ("seed = true", "run.seed"),
        ("seed = -3", "run.seed"),
        ("[world]\nspawn = 2.0", "world.spawn"),
        ("planning_speed = -inf", "run.planning_speed"),
        ("lockstep = 1", "run.lockstep"),
    ],
)
def test_scenario_values_out_of_range_name_the_field(tmp_path: Path, run: str, field: str) -> None:
    path = scenario(tmp_path, run)
    with pytest.raises(CbdiError, match=f"{path}: {field}: "):
        load_scenario(path)


def test_a_simulator_that_is_not_installed_is_named_with_those_that_are(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text(
        f'name = "s"\nmap = "{MAP}"\n[run]\nsimulator = "warehouse"\n[[agents]]\nname = "robot1"\n'
    )
    with pytest.raises(
        CbdiError,
        match=r"run.simulator: simulator: no simulator 'warehouse' "
        r"\(installed: clock, courier, recycling\)",
    ):
        load_scenario(path)


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("plan_size_limit = 8", "plan_size_limit = -1", "planning.plan_size_limit"),
        ("round_interval = 0.1", "round_interval = -inf", "planning.round_interval"),
        ("round_interval = 0.1", "round_interval = nan", "planning.round_interval"),
        (
            "expansions_per_round = 200",
            "expansions_per_round = -1",
            "planning.expansions_per_round",
        ),
        ("priority = 0.8", "priority = 8", r"rules\[0\].then\[0\].boost.priority"),
        ("deadline = 64", "deadline = nan", r"rules\[0\].then\[0\].boost.deadline"),
        ("plan_retries = 3", "plan_retries = -2", "scheduler.plan_retries"),
        ('"(holding {self} {x})"', '"(holdin {self} {x})"', r"rules\[1\].when\[0\]\[2\]"),
        ('"(recycled {x})"', '"(recycle {x})"', r"rules\[0\].then\[0\].boost.goal\[0\]"),
        ('"(in {self} {x})"', '"(in {x})"', r"rules\[2\].then\[1\].add_desire.goal\[0\]"),
        ('"(map_loaded)",\n', '"(map_loaded)", "(should_patrol c_1_1 c_2_2)",\n', "beliefs"),
        ('"(= (loaded_amount {self}) 0)"', '"(= (loaded_amount {self}) nan)"', r"beliefs\[2\]"),
    ],
)
def test_agent_file_mistakes_name_the_field(tmp_path: Path, old: str, new: str, field: str) -> None:
    path = agent(tmp_path, old, new)
    if "should_patrol c_1_1" in new:  # private beliefs take any arguments, but not goals
        load_agent(path, "robot1")
        return
    with pytest.raises(CbdiError, match=f"{path}: {field}: "):
        load_agent(path, "robot1")


def test_a_goal_over_a_private_predicate_is_refused(tmp_path: Path) -> None:
    path = agent(tmp_path, '"(recycled {x})"', '"(should_patrol {x})"')
    with pytest.raises(CbdiError, match=r"'should_patrol' is not declared by the domain$"):
        load_agent(path, "robot1")


def test_map_numbers_must_be_finite(tmp_path: Path) -> None:
    path = tmp_path / "m.toml"
    text = MAP.read_text()
    assert "epoch_duration = 1.0" in text
    path.write_text(text.replace("epoch_duration = 1.0", "epoch_duration = inf"))
    with pytest.raises(CbdiError, match="epoch_duration: expected a finite number > 0"):
        load_map(path)


def damaged(data: bytes, rng: random.Random) -> bytes:
    i = rng.randrange(len(data))
    kind = rng.randrange(4)
    if kind == 0:
        return data[:i]
    if kind == 1:
        return data[:i] + bytes([rng.randrange(256)]) + data[i + 1 :]
    if kind == 2:
        return data[:i] + data[i + rng.randint(1, 30) :]
    j = rng.randrange(len(data))
    return data[:i] + data[j : j + rng.randint(1, 30)] + data[i:]


@pytest.mark.parametrize("kind", sorted(LOADERS))
def test_damaged_shipped_files_load_or_give_a_named_error(kind: str, tmp_path: Path) -> None:
    """The files keep their relative paths (the domain and the map are copied beside
    them), so the damage is the same wherever the project is checked out."""
    original, load = LOADERS[kind]
    data = original.read_bytes()
    for folder in ("pddl", "maps", "agents"):
        (tmp_path / folder).mkdir()
    for source in (DOMAIN, MAP, AGENT):
        (tmp_path / source.parent.name / source.name).write_bytes(source.read_bytes())
    rng = random.Random(f"config:{kind}")
    (tmp_path / "files").mkdir()
    path = tmp_path / "files" / original.name
    errors = 0
    for _ in range(400):
        path.write_bytes(damaged(data, rng))
        try:
            load(path)
        except CbdiError as exc:
            errors += 1
            assert str(path) in str(exc), exc
    assert errors > 30


def test_cbdi_up_exits_2_for_a_bad_scenario(tmp_path: Path) -> None:
    for run in ("until = []", "max_time = -5"):
        path = scenario(tmp_path, run)
        done = subprocess.run([str(CBDI), "up", str(path)], capture_output=True, text=True)
        assert done.returncode == 2, done.stderr
        assert "Traceback" not in done.stderr and str(path) in done.stderr
    done = subprocess.run(
        [str(CBDI), "up", "paper-7x7", "--until", "-1"], capture_output=True, text=True
    )
    assert done.returncode == 2 and "--until" in done.stderr


def test_a_domain_action_nobody_performs_stops_cbdi_up_before_it_starts(tmp_path: Path) -> None:
    """The recycling domain with `move` renamed `drive`: the world performs no `drive`,
    so `cbdi up` says so (file, line, action, what the world does) and starts nothing;
    an agent file that names a performer for it passes the check."""
    domain = tmp_path / "domain.pddl"
    renamed = DOMAIN.read_text().replace("(:durative-action move", "(:durative-action drive")
    assert renamed != DOMAIN.read_text()
    domain.write_text(renamed)
    line = renamed[: renamed.index("(:durative-action drive")].count("\n") + 1
    for performers in ("", 'performers = ["drive"]\n'):
        text = AGENT.read_text().replace('domain = "../pddl/domain.pddl"', f'domain = "{domain}"')
        (tmp_path / "agent.toml").write_text(performers + text)
        path = tmp_path / "s.toml"
        path.write_text(
            f'name = "s"\nmap = "{MAP}"\n[run]\nsimulator = "recycling"\n'
            '[[agents]]\nname = "robot1"\nkind = "bdi"\n'
            f'agent_file = "{tmp_path / "agent.toml"}"\n'
        )
        if performers:
            scenario = load_scenario(path)
            assert scenario.agents[0].name == "robot1"
            # In lockstep the robot's own process (cbdi.robot) is a member the world
            # waits for; in real time it is not.
            for lockstep in (True, False):
                run = dataclasses.replace(scenario.run, lockstep=lockstep)
                args = world_args(dataclasses.replace(scenario, run=run))
                members = [args[i + 1] for i, a in enumerate(args) if a == "--member"]
                assert ("robot1/performer" in members) is lockstep, members
            continue
        with pytest.raises(CbdiError, match=rf"{domain}:{line}: action drive: nobody performs"):
            load_scenario(path)
        done = subprocess.run([str(CBDI), "up", str(path)], capture_output=True, text=True)
        assert done.returncode == 2 and "Traceback" not in done.stderr
        assert "performs move, litter_pickup, recycle" in done.stderr, done.stderr
        assert "started service" not in done.stderr
    bad = tmp_path / "agent.toml"
    bad.write_text(
        'performers = ["fly"]\n'
        + AGENT.read_text().replace('domain = "../pddl/domain.pddl"', f'domain = "{DOMAIN}"')
    )
    with pytest.raises(CbdiError, match="performers: the domain has no action 'fly'"):
        load_agent(bad, "robot1")


def test_cbdi_up_exits_2_for_a_search_core_that_does_not_exist() -> None:
    """A mistyped CBDI_SEARCH_CORE stops the run before it starts (the planner used to
    log it and plan nothing, and the run ended incomplete)."""
    env = {**os.environ, "CBDI_SEARCH_CORE": "bogus"}
    done = subprocess.run(
        [str(CBDI), "up", "paper-7x7", "--json", "--quiet"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert done.returncode == 2, done.stderr
    assert "robot1/planner" in done.stderr and "CBDI_SEARCH_CORE='bogus'" in done.stderr


def test_a_scenario_gives_an_agent_s_actions_to_its_body(tmp_path: Path) -> None:
    """`performers` in a scenario's agent entry: added to the agent file's, for this run
    (the executor sends those steps to the robot's process, which in lockstep is a
    member); anything but a list of action names is refused, naming the field."""
    path = tmp_path / "s.toml"
    head = f'name = "s"\nmap = "{MAP}"\n[run]\nsimulator = "recycling"\nlockstep = true\n'
    entry = f'[[agents]]\nname = "robot1"\nkind = "bdi"\nagent_file = "{AGENT}"\n'
    path.write_text(head + entry + 'performers = ["MOVE"]\n')
    scenario = load_scenario(path)
    assert scenario.agents[0].performers == ("move",)
    args = world_args(scenario)
    assert "robot1/performer" in [args[i + 1] for i, a in enumerate(args) if a == "--member"]
    plans = plan_services(scenario, "tcp/127.0.0.1:7447")
    executor = next(p for p in plans if p.service == "robot1/executor")
    assert "--performer" in executor.args and "move" in executor.args
    for bad, why in (('"move"', "list of action names"), ('["move it"]', "performers[0]")):
        path.write_text(head + entry + f"performers = {bad}\n")
        with pytest.raises(CbdiError, match=rf"agents\[0\]\.performers.*|{why}"):
            load_scenario(path)
