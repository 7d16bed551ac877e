"""`cbdi compose`: the compose services are `cbdi up`'s, with the same arguments."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from cbdi.errors import ConfigError
from cbdi.launcher import compose
from cbdi.launcher.compose import ComposeOptions, compose_file
from cbdi.launcher.scenario import find_scenario, load_scenario
from cbdi.launcher.specs import run_specs as _specs
from cbdi.launcher.wait import exit_code

REPO = Path(__file__).resolve().parents[2]
DOMAINS = str(REPO / "domains")


def _scenario(agents: int = 2):  # type: ignore[no-untyped-def]
    return load_scenario(find_scenario("paper-7x7")).with_agents(agents)


def _commands(text: str) -> dict[str, list[str]]:
    """Each service's command, read back from the generated YAML (flow lists are JSON)."""
    import json

    out: dict[str, list[str]] = {}
    service = ""
    for line in text.splitlines():
        if line.startswith("  ") and not line.startswith("   ") and line.endswith(":"):
            service = line.strip()[:-1]
        elif line.strip().startswith("command: "):
            out[service] = json.loads(line.strip()[len("command: ") :])
    return out


def test_every_service_gets_the_arguments_cbdi_up_gives_it() -> None:
    scenario = _scenario()
    commands = _commands(compose_file(scenario, ComposeOptions()))
    for spec in _specs(scenario, "tcp/127.0.0.1:1", "/runs/paper-7x7.mcap"):
        if spec.service == "router":
            continue
        args = [a.replace(DOMAINS, "/opt/cbdi/domains") for a in spec.args]
        command = commands[spec.service.replace("/", "-")]
        assert command[1 : 1 + len(args)] == args, spec.service
    world = commands["world"]
    members = [world[i + 1] for i, a in enumerate(world) if a == "--member"]
    assert len(members) == 6 and "robot2/planner" in members
    assert "--stop-when-done" in world and "--wait-agents" in world
    assert commands["wait"][:4] == ["cbdi", "wait", "--until", "done"]


def test_a_run_splits_over_two_projects_with_joined_routers() -> None:
    scenario = _scenario()
    here = ComposeOptions(network="host", port=17447, only=("world", "robot1"))
    there = ComposeOptions(
        network="host", port=17448, only=("robot2",), join=("tcp/127.0.0.1:17447",)
    )
    # The hub's router has the hub's id; the joining one logs in to it as `router`.
    hub, joiner = compose_file(scenario, here), compose_file(scenario, there)
    assert "CBDI_ZENOH_CONFIG: /secrets/router/hub.json" in hub
    assert "CBDI_ZENOH_CONFIG" not in joiner
    assert "CBDI_CREDENTIALS: /secrets/credentials/router.json" in joiner
    first = _commands(compose_file(scenario, here))
    second = _commands(compose_file(scenario, there))
    assert set(first) == {"router", "monitor", "world", "wait"} | {
        f"robot1-{c}" for c in ("planner", "scheduler", "executor")
    }
    assert set(second) == {"router"} | {f"robot2-{c}" for c in ("planner", "scheduler", "executor")}
    assert second["router"][-2:] == ["--connect", "tcp/127.0.0.1:17447"]
    assert "tcp/127.0.0.1:17448" in second["router"]
    assert "CBDI_CONNECT: tcp/127.0.0.1:17448" in compose_file(scenario, there)


def test_every_service_logs_in_with_its_own_credentials_mounted_read_only() -> None:
    text = compose_file(_scenario(), ComposeOptions())
    assert "CBDI_CREDENTIALS: /secrets/credentials/robot2.executor.json" in text
    assert "CBDI_ACL: /secrets/router/acl.json" in text
    # Read-only but for the router, which makes them when they are missing.
    assert text.count('"./secrets:/secrets:ro"') == text.count("    image: ") - 1
    router = text[text.index("  router:") : text.index("  monitor:")]
    assert '"./secrets:/secrets"' in router and "CBDI_SECRETS_DIR: /secrets" in router
    # With each agent's group: its scheduler may ask the others under it (a rule's ask).
    assert 'CBDI_SECRETS_AGENTS: "robot1:bdi:recyclers,robot2:bdi:recyclers"' in router
    assert "CBDI_CREDENTIALS" not in compose_file(_scenario(), ComposeOptions(secrets=""))


def test_the_world_keeps_its_state_in_its_containers_own_volume() -> None:
    """Restarted by the restart policy (not by `cbdi up`, which says so), the world goes
    on from the state file it finds in its own volume (tests/world/test_restart.py)."""
    text = compose_file(_scenario(), ComposeOptions())
    world = text[text.index("  world:") : text.index("  robot1-planner:")]
    assert "CBDI_STATE: /state/world.state" in world and "CBDI_RESUME: if-found" in world
    assert '"/state"]' in world and "restart: on-failure" in world
    assert text.count("CBDI_STATE") == 1


def test_unknown_parts_and_files_outside_domains_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(ConfigError, match="--only"):
        compose_file(_scenario(), ComposeOptions(only=("robot9",)))
    scenario_file = tmp_path / "mine.toml"
    text = (REPO / "domains/recycling/scenarios/paper-7x7.toml").read_text()
    map_file = REPO / "domains/recycling/maps/paper-7x7.toml"
    (tmp_path / "map.toml").write_text(map_file.read_text())
    agents = REPO / "domains/recycling/agents"
    text = text.replace('"../maps/paper-7x7.toml"', '"map.toml"')
    text = text.replace('"../agents', f'"{agents}')
    scenario_file.write_text(text)
    assert compose.main([str(scenario_file), "-o", str(tmp_path / "x.yml")]) == 2
    assert "not under domains/" in capsys.readouterr().err


@pytest.mark.skipif(not shutil.which("docker-compose"), reason="docker-compose is missing")
def test_compose_accepts_the_generated_file(tmp_path: Path) -> None:
    path = tmp_path / "run.yml"
    path.write_text(compose_file(_scenario(3), ComposeOptions(publish=True, timeout=60)))
    result = subprocess.run(
        ["docker-compose", "-f", str(path), "config", "-q"], capture_output=True, text=True
    )
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize(
    ("reason", "until", "code"),
    [("done", "done", 0), ("time_limit", "done", 3), ("time_limit", "time_limit", 0),
     ("interrupted", "done", 1)],
)  # fmt: skip
def test_wait_exits_with_the_runs_result(reason: str, until: str, code: int) -> None:
    assert exit_code(reason, until) == code


def _mounts(text: str) -> set[str]:
    """Every bind mount's host side, read back from the generated YAML."""
    import json

    found: set[str] = set()
    for line in text.splitlines():
        if line.strip().startswith("volumes: "):
            mounts = json.loads(line.strip()[len("volumes: ") :])
            found |= {v.split(":")[0] for v in mounts if ":" in v}  # not anonymous ones
    return found


def test_compose_from_another_directory_writes_the_secrets_beside_the_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Compose resolves `./secrets` from the compose file's folder: `cbdi compose -o
    DIR/dc.yml` run elsewhere writes them in DIR/secrets, none where it ran."""
    elsewhere, out = tmp_path / "cwd", tmp_path / "deploy" / "dc.yml"
    elsewhere.mkdir()
    out.parent.mkdir()
    monkeypatch.chdir(elsewhere)
    assert compose.main(["paper-7x7", "--agents", "2", "-o", str(out)]) == 0
    assert str(out.parent / "secrets") in capsys.readouterr().err
    assert not (elsewhere / "secrets").exists()
    text = out.read_text()
    mounted = {(out.parent / m).resolve() for m in _mounts(text) if m != "./runs"}
    assert mounted == {(out.parent / "secrets").resolve()}
    for service, env in (("robot2-executor", "CBDI_CREDENTIALS"), ("router", "CBDI_ACL")):
        block = text[text.index(f"  {service}:") :]
        inside = block[block.index(f"{env}: ") + len(env) + 2 :].split("\n", 1)[0]
        on_host = out.parent / "secrets" / Path(inside).relative_to("/secrets")
        assert on_host.is_file() and on_host.stat().st_mode & 0o777 == 0o600, on_host
    # An absolute --secrets stays where it is named.
    shared = tmp_path / "shared-secrets"
    assert compose.main(["paper-7x7", "-o", str(out), "--secrets", str(shared)]) == 0
    assert (shared / "router" / "acl.json").is_file()


def test_the_router_makes_the_secrets_every_service_names_when_missing(tmp_path: Path) -> None:
    """A fresh clone has no ./secrets: the compose run's router makes the ones every
    container's environment names (into the directory they all mount), and keeps them."""
    from cbdi.router import RouterSettings, make_secrets

    where = tmp_path / "secrets"
    text = compose_file(_scenario(), ComposeOptions())
    settings = RouterSettings(secrets_dir=str(where), secrets_agents=("robot1:bdi", "robot2:bdi"))
    assert make_secrets(settings)
    named = [line.split(": ", 1)[1] for line in text.splitlines() if "/secrets/" in line]
    assert len(named) == 13  # 10 credentials, the users, the ACL, the hub's id
    for inside in named:
        assert (where / Path(inside).relative_to("/secrets")).is_file(), inside
    acl = (where / "router" / "acl.json").read_text()
    assert not make_secrets(settings) and (where / "router" / "acl.json").read_text() == acl
    with pytest.raises(ConfigError, match="NAME:KIND"):
        make_secrets(RouterSettings(secrets_dir=str(where), secrets_agents=("robot1",)))
    grouped = tmp_path / "grouped"
    make_secrets(RouterSettings(secrets_dir=str(grouped), secrets_agents=("robot1:bdi:team",)))
    acl = (grouped / "router" / "acl.json").read_text()
    assert "cbdi/*/scheduler/rpc/request/team" in acl
