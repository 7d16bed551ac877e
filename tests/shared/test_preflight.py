"""`cbdi up` refuses a bad agent file, map, domain or scenario before anything starts:
exit 2, the message naming the service and the file, no process spawned, no port bound
(`cbdi.launcher.preflight`: every service built by its own shell first)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cbdi.errors import ConfigError
from cbdi.launcher.preflight import check_services
from cbdi.launcher.scenario import find_scenario, load_scenario
from tests_support import REPO, free_port

RECYCLING = REPO / "domains" / "recycling"
TRUE = "subprocess.Popen ('true', ['true'], None, None)"  # the spawn the driver makes
# Runs `cbdi up` in a process that records, through an audit hook, every process it
# would spawn and every socket it would bind or connect; `true` is spawned first, so
# that the test knows the hook sees a spawn.
DRIVER = """
import json, os, subprocess, sys
seen = []
WATCHED = ("subprocess.Popen", "os.posix_spawn", "os.fork", "os.exec", "os.system",
           "socket.bind", "socket.connect")

def hook(event, args):
    # ctypes.util.find_library runs `ldconfig -p` when a library is imported: no child
    # of the run
    if event in WATCHED and "ldconfig" not in str(args):
        seen.append(f"{event} {str(args)[:200]}")

sys.addaudithook(hook)
subprocess.run(["true"], check=True)
from cbdi.launcher.cli import main
try:
    code = main(sys.argv[1:])
finally:
    with open(os.environ["SEEN"], "w") as f:
        json.dump(seen, f)
sys.exit(code)
"""


def _scenario(tmp_path: Path, agent_file: Path, map_file: Path) -> Path:
    text = (RECYCLING / "scenarios" / "paper-7x7.toml").read_text()
    text = text.replace('"../maps/paper-7x7.toml"', json.dumps(str(map_file)))
    text = text.replace('"../agents/recycler.toml"', json.dumps(str(agent_file)))
    path = tmp_path / "scenario.toml"
    path.write_text(text)
    return path


def _agent_file(tmp_path: Path, old: str = "", new: str = "") -> Path:
    text = (RECYCLING / "agents" / "recycler.toml").read_text()
    text = text.replace("../pddl/", f"{RECYCLING}/pddl/")
    assert old in text
    text = text.replace(old, new)
    path = tmp_path / "agent.toml"
    path.write_text(text)
    return path


def _up(tmp_path: Path, scenario: Path) -> tuple[subprocess.CompletedProcess[str], list[str]]:
    seen = tmp_path / "seen.json"
    runs = tmp_path / "runs"
    env = {**os.environ, "SEEN": str(seen), "CBDI_RUNS_DIR": str(runs)}
    port = str(free_port())
    result = subprocess.run(
        [sys.executable, "-c", DRIVER, str(scenario), "--port", port, "--quiet"],
        capture_output=True, text=True, timeout=120, cwd=tmp_path, env=env,
        stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert not runs.exists()  # no run directory: the router's secrets were never made
    return result, json.loads(seen.read_text())


def test_a_bad_agent_file_is_refused_before_any_process_starts(tmp_path: Path) -> None:
    """Only the scheduler's loader reads `scheduler.preemption`: today's run started the
    router and the world, then the scheduler exited 2, and `cbdi up` 1."""
    bad = _agent_file(tmp_path, 'preemption = "clean_preempt"', 'preemption = "sometimes"')
    scenario = _scenario(tmp_path, bad, RECYCLING / "maps" / "paper-7x7.toml")
    result, seen = _up(tmp_path, scenario)
    assert result.returncode == 2, result.stderr[-2000:]
    assert "robot1/scheduler" in result.stderr and str(bad) in result.stderr, result.stderr
    assert "preemption" in result.stderr
    assert seen == [TRUE], seen  # `true` alone: nothing spawned, nothing bound


def test_a_bad_map_is_refused_before_any_process_starts(tmp_path: Path) -> None:
    bad_map = tmp_path / "bad-map.toml"
    bad_map.write_text('name = "bad"\ngrid = """\nBA.\n.x.\n"""\n')
    agent = _agent_file(tmp_path)
    result, seen = _up(tmp_path, _scenario(tmp_path, agent, bad_map))
    assert result.returncode == 2, result.stderr[-2000:]
    assert "world" in result.stderr and "bad-map.toml" in result.stderr, result.stderr
    assert "unknown cell 'x'" in result.stderr
    assert seen == [TRUE], seen


def test_a_bad_pddl_domain_names_the_planner_and_the_line(tmp_path: Path) -> None:
    domain = tmp_path / "domain.pddl"
    text = (RECYCLING / "pddl" / "domain.pddl").read_text()
    domain.write_text(text.replace(":parameters", ":parameterz", 1))
    agent = _agent_file(tmp_path, f"{RECYCLING}/pddl/domain.pddl", str(domain))
    scenario = load_scenario(_scenario(tmp_path, agent, RECYCLING / "maps" / "paper-7x7.toml"))
    with pytest.raises(ConfigError, match=r"robot1/planner.*domain\.pddl:\d+:\d+.*:parameterz"):
        check_services(scenario)


def test_the_shipped_scenarios_pass_the_check() -> None:
    for name in ("paper-7x7", "corridor", "paper-7x7-scripted", "courier"):
        check_services(load_scenario(find_scenario(name)))
    check_services(load_scenario(find_scenario("paper-7x7")).with_agents(3))


def test_more_agents_than_the_map_has_starts_are_refused_by_the_world() -> None:
    with pytest.raises(ConfigError, match="world: refused: 2 agents but the map has only 1"):
        check_services(load_scenario(find_scenario("corridor")).with_agents(2))
