"""docker-compose.yml is valid (checked offline by Compose) and runs what exists."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

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


def test_compose_runs_router_world_and_a_bdi_agent_against_the_router() -> None:
    result = _config(REPO / "docker-compose.yml", "--services")
    assert result.returncode == 0, result.stderr
    services = {"router", "monitor", "world", "robot1-planner", "robot1-scheduler"}
    assert services | {"robot1-executor"} <= set(result.stdout.split())
    full = _config(REPO / "docker-compose.yml").stdout
    assert "CBDI_CONNECT: tcp/router:7447" in full
    assert "BASE_IMAGE" in full


def test_the_validator_rejects_a_broken_file(tmp_path: Path) -> None:
    broken = tmp_path / "docker-compose.yml"
    broken.write_text("services:\n  x:\n    image: a\n    ports: 7\n    nonsense_key: 1\n")
    assert _config(broken, "-q").returncode != 0


@pytest.mark.parametrize("name", ["Dockerfile"])
def test_dockerfile_base_image_is_a_build_argument(name: str) -> None:
    text = (REPO / name).read_text()
    assert "ARG BASE_IMAGE=" in text and "FROM ${BASE_IMAGE}" in text
