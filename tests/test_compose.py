"""docker-compose.yml is valid (checked offline by Compose) and runs what exists."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from cbdi.launcher import compose

REPO = Path(__file__).resolve().parents[1]
COMPOSE = shutil.which("docker-compose")


def _config(path: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    assert COMPOSE, "docker-compose is missing: `make test` installs it (Debian package)"
    return subprocess.run(
        [COMPOSE, "-f", str(path), "config", *extra],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=path.parent,
    )


def test_compose_file_is_valid() -> None:
    result = _config(REPO / "docker-compose.yml", "-q")
    assert result.returncode == 0, result.stderr


def test_compose_runs_router_world_two_bdi_agents_and_wait_against_the_router() -> None:
    result = _config(REPO / "docker-compose.yml", "--services")
    assert result.returncode == 0, result.stderr
    robots = {f"robot{i}-{c}" for i in (1, 2) for c in ("planner", "scheduler", "executor")}
    assert set(result.stdout.split()) == {"router", "monitor", "world", "wait"} | robots
    full = _config(REPO / "docker-compose.yml").stdout
    assert "CBDI_CONNECT: tcp/router:7447" in full
    assert "--stop-when-done" in full


def test_the_committed_compose_file_is_what_cbdi_compose_writes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)  # its secrets go to ./secrets
    out = tmp_path / "docker-compose.yml"
    assert compose.main(["paper-7x7", "--agents", "2", "-o", str(out)]) == 0
    assert out.read_text() == (REPO / "docker-compose.yml").read_text(), (
        "regenerate it: cbdi compose paper-7x7 --agents 2 -o docker-compose.yml"
    )
    creds = tmp_path / "secrets" / "credentials" / "robot1.executor.json"
    assert creds.stat().st_mode & 0o777 == 0o600
    written = creds.read_text()
    assert compose.main(["paper-7x7", "--agents", "2", "-o", str(out)]) == 0
    assert creds.read_text() == written  # kept: a split run's projects share them


def test_the_validator_rejects_a_broken_file(tmp_path: Path) -> None:
    broken = tmp_path / "docker-compose.yml"
    broken.write_text("services:\n  x:\n    image: a\n    ports: 7\n    nonsense_key: 1\n")
    assert _config(broken, "-q").returncode != 0


@pytest.mark.parametrize("name", ["Dockerfile"])
def test_dockerfile_base_image_is_a_build_argument(name: str) -> None:
    text = (REPO / name).read_text()
    assert "ARG BASE_IMAGE=" in text and "FROM ${BASE_IMAGE}" in text
