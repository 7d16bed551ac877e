"""A scenario's `[world]` options and `cbdi up --option` reach the simulator `cbdi-world`
hosts (the recycling grid's chances here), checked by what the simulator declares."""

from __future__ import annotations

from pathlib import Path

import pytest
from cbdi_recycling.chance import Chance

from cbdi.errors import ConfigError
from cbdi.launcher import cli
from cbdi.launcher.scenario import find_scenario, load_scenario
from cbdi.launcher.specs import run_specs as _specs
from cbdi.runtime import load_config
from cbdi_world.service import WorldSettings, build_world

REPO = Path(__file__).resolve().parents[2]
MAP = REPO / "domains" / "recycling" / "maps" / "paper-7x7.toml"


def scenario_file(tmp_path: Path, run: str) -> Path:
    path = tmp_path / "s.toml"
    head = f'name = "s"\nmap = "{MAP}"\n[run]\nsimulator = "recycling"\n[world]\n'
    path.write_text(f'{head}{run}\n[[agents]]\nname = "robot1"\n')
    return path


def world_of(argv: list[str]) -> Chance:
    """Build the world `cbdi up ARGV` would start and return its chances."""
    scenario = cli.scenario_from_args(cli._parser().parse_args(argv))
    world_argv = next(s.argv for s in _specs(scenario, "tcp/127.0.0.1:1") if s.service == "world")
    args = world_argv[world_argv.index("--map") :]
    return build_world(load_config(WorldSettings, args, prog="w", section="world", env={})).chance


def test_the_paper_scenario_samples_a_phase_and_a_jitter_of_its_people() -> None:
    scenario = load_scenario(find_scenario("paper-7x7"))
    assert scenario.options == {"people_phase": True, "people_jitter": 1}
    assert world_of(["paper-7x7"]) == Chance(people_phase=True, people_jitter=1)


def test_flags_override_the_scenario_and_reach_the_world() -> None:
    argv = ["paper-7x7", "--option", "people_phase=false", "--option", "people-jitter=3"]
    argv += ["--option", "duration_noise=0.25", "--option", "failure_probability=0.1"]
    assert world_of(argv) == Chance(
        people_phase=False, people_jitter=3, duration_noise=0.25, failure_probability=0.1
    )
    assert world_of(["corridor"]) == Chance()  # off unless asked


@pytest.mark.parametrize(
    ("run", "field"),
    [
        ("people_jitter = -1", "world.people_jitter"),
        ("people_jitter = true", "world.people_jitter"),
        ("people_jitter = 1.5", "world.people_jitter"),
        ("duration_noise = 11", "world.duration_noise"),
        ("duration_noise = nan", "world.duration_noise"),
        ("failure_probability = 1.0", "world.failure_probability"),
        ("failure_probability = inf", "world.failure_probability"),
        ("people_phase = 1", "world.people_phase"),
        ("peoples_phase = true", "world.peoples_phase"),
    ],
)
def test_bad_run_values_name_the_key(tmp_path: Path, run: str, field: str) -> None:
    with pytest.raises(ConfigError) as caught:
        load_scenario(scenario_file(tmp_path, run))
    assert caught.value.field == field


@pytest.mark.parametrize(
    "flags",
    [
        "people_jitter=-1",
        "duration_noise=-0.5",
        "duration_noise=nan",
        "failure_probability=1",
        "people_phase=maybe",
    ],
)
def test_bad_options_exit_2_naming_the_option(flags: str, capsys: pytest.CaptureFixture) -> None:
    assert cli.main(["paper-7x7", "--option", flags]) == cli.EXIT_USAGE
    assert f"cbdi up: --option: {flags.split('=')[0]}: expected" in capsys.readouterr().err


def test_an_unknown_option_is_refused_with_the_known_ones(capsys: pytest.CaptureFixture) -> None:
    assert cli.main(["paper-7x7", "--option", "move_stp=4"]) == cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert "--option: move_stp: unknown option of GridWorld" in err and "move_step" in err
    assert cli.main(["courier", "--option", "move_step=4"]) == cli.EXIT_USAGE
    assert "unknown option of CourierSimulator (it has: none)" in capsys.readouterr().err


def test_a_scenario_without_a_simulator_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text(f'name = "s"\nmap = "{MAP}"\n[run]\n[[agents]]\nname = "robot1"\n')
    with pytest.raises(ConfigError, match=r"run\.simulator: missing"):
        load_scenario(path)


def test_each_service_is_told_its_args_and_the_launcher_records_them() -> None:
    # What `RunLaunched` carries: the end of each argv, enough to build the service again.
    scenario = cli.scenario_from_args(cli._parser().parse_args(["paper-7x7", "--mode", "offline"]))
    specs = {s.service: s for s in _specs(scenario, "tcp/127.0.0.1:1")}
    for spec in specs.values():
        assert spec.args and spec.argv[-len(spec.args) :] == spec.args
    planner = list(specs["robot1/planner"].args)
    agent_file = planner[planner.index("--agent-file") + 1]
    assert Path(agent_file).is_absolute() and Path(agent_file).name == "recycler.toml"
    assert planner[planner.index("--planning") + 1] == "offline"


def test_only_the_world_is_told_its_state_file_and_not_in_its_args() -> None:
    # In the environment: the recorded arguments (and `cbdi compose`'s) stay the same.
    scenario = cli.scenario_from_args(cli._parser().parse_args(["paper-7x7"]))
    plain = {s.service: s for s in _specs(scenario, "tcp/127.0.0.1:1")}
    kept = {s.service: s for s in _specs(scenario, "tcp/127.0.0.1:1", state="/run/world.state")}
    assert kept["world"].env["CBDI_STATE"] == "/run/world.state"
    assert kept["world"].args == plain["world"].args and "CBDI_STATE" not in plain["world"].env
    assert not any("CBDI_STATE" in s.env for name, s in kept.items() if name != "world")


def test_one_process_per_agent_runs_its_components_with_the_same_args() -> None:
    scenario = cli.scenario_from_args(cli._parser().parse_args(["paper-7x7", "--agents", "2"]))
    alone = {s.service: s for s in _specs(scenario, "tcp/127.0.0.1:1")}
    hosted = {s.service: s for s in _specs(scenario, "tcp/127.0.0.1:1", agent_process=True)}
    assert set(hosted) == {"router", "world", "robot1/agent", "robot2/agent"}
    assert hosted["world"] == alone["world"]
    agent = hosted["robot2/agent"]
    assert agent.members == ("robot2/planner", "robot2/scheduler", "robot2/executor")
    sections = " ".join(agent.args).split(" -- ")
    assert sections[0].split(" ")[0] == "agent"
    for component, section in zip(("planner", "scheduler", "executor"), sections, strict=True):
        words = section.split(" ")[1:] if component == "planner" else section.split(" ")
        assert words[0] == component
        assert tuple(words[1:]) == alone[f"robot2/{component}"].args
    assert alone["world"].members == ("world",)
