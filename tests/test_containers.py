"""Two BDI robots in containers: the image from a fresh clone, the paper run to its end.

Podman runs the containers (no Docker engine here; `make test` installs it), driven by
Compose v1 (`docker-compose`) through `podman system service`, as docs/containers.md
says. The base image is cached (Podman's store and ~/.cache/cbdi), so after the first
run (about 3 min, debootstrap) this test takes well under a minute.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PODMAN = shutil.which("podman")
COMPOSE = shutil.which("docker-compose")
BIN = Path(sys.executable).parent


def _podman_runs() -> str:
    """Return why containers cannot run here ('' when they can)."""
    if not PODMAN:
        return "podman is not installed and `make system-tools` could not install it"
    if not COMPOSE:
        return "docker-compose is not installed and `make system-tools` could not install it"
    info = subprocess.run([PODMAN, "info"], capture_output=True, text=True, timeout=120)
    if info.returncode != 0:
        return f"podman cannot run here: {info.stderr.strip()[-300:]}"
    return ""


WHY_NOT = _podman_runs()
pytestmark = pytest.mark.skipif(bool(WHY_NOT), reason=WHY_NOT)


def _run(
    argv: list[str], cwd: Path, timeout: float, **env: str
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        argv,
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **env},
    )


@pytest.fixture
def podman_socket(tmp_path: Path) -> Iterator[str]:
    """A Docker API on a socket of ours, served by Podman, for docker-compose."""
    socket = tmp_path / "podman.sock"
    assert PODMAN is not None
    service = subprocess.Popen(
        [PODMAN, "system", "service", "--time", "0", f"unix://{socket}"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 30
        while not socket.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert socket.exists(), "podman system service did not open its socket"
        yield f"unix://{socket}"
    finally:
        service.terminate()
        service.wait(timeout=30)


def test_two_bdi_robots_in_containers_recycle_everything(
    tmp_path: Path, podman_socket: str
) -> None:
    clone = tmp_path / "clone"
    cloned = _run(["git", "clone", "-q", str(REPO), str(clone)], tmp_path, 120)
    assert cloned.returncode == 0, cloned.stderr
    image = f"localhost/cbdi-test:{os.getpid()}"
    project = f"cbdi-test-{os.getpid()}"
    env = {"CBDI_ENGINE": "podman", "CBDI_IMAGE": image, "DOCKER_HOST": podman_socket}
    started = time.monotonic()
    built = _run(["sh", "tools/image.sh"], clone, 900, **env)
    assert built.returncode == 0, built.stderr[-3000:]
    build_s = time.monotonic() - started
    compose_file = tmp_path / "run.yml"
    compose = [COMPOSE or "docker-compose", "-f", str(compose_file), "-p", project]
    try:
        # The generator inside the image: its paths are the image's.
        generated = _run(
            [PODMAN or "podman", "run", "--rm", "--ulimit", "nofile=4096:4096",
             "--ulimit", "nproc=4096:4096", image,
             "cbdi", "compose", "paper-7x7", "--agents", "2", "--runs", str(tmp_path / "runs"),
             "--timeout", "600"],
            clone, 120,
        )  # fmt: skip
        assert generated.returncode == 0, generated.stderr
        compose_file.write_text(generated.stdout)
        (tmp_path / "runs").mkdir()
        up = _run([*compose, "up", "--exit-code-from", "wait"], tmp_path, 900, **env)
        run_s = time.monotonic() - started - build_s
        assert up.returncode == 0, up.stdout[-4000:] + up.stderr[-2000:]
    finally:
        _run([*compose, "down"], tmp_path, 300, **env)
        _run([PODMAN or "podman", "rmi", image], tmp_path, 120)
    print(f"image built in {build_s:.0f} s, run in {run_s:.0f} s")
    recording = tmp_path / "runs" / "paper-7x7.mcap"
    inspected = _run([str(BIN / "cbdi"), "inspect", "--json", str(recording)], tmp_path, 120)
    assert inspected.returncode == 0, inspected.stderr
    report = json.loads(inspected.stdout)
    assert report["result"] == "done"
    recycled = {name: agent["recycled"] for name, agent in report["agents"].items()}
    assert set(recycled) == {"robot1", "robot2"} and all(n > 0 for n in recycled.values())
    rerun = shutil.which("rerun", path=str(BIN)) or shutil.which("rerun")
    assert rerun, "rerun (rerun-sdk, a dev dependency) is missing"
    checked = _run([rerun, "mcap", "check", str(recording)], tmp_path, 120)
    assert checked.returncode == 0, checked.stdout[-2000:]
