"""The generic services run the courier domain in a fresh environment where the recycling
package is not installed: nothing generic needs it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests_support import REPO, free_port

pytestmark = pytest.mark.e2e

GENERIC = ["shared", "services/world", "services/monitor", "services/scheduler"]
GENERIC += ["services/executor", "services/planner", "domains/courier"]


def run(*argv: str | Path, cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(a) for a in argv],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
        stdin=subprocess.DEVNULL,
    )


@pytest.mark.timeout(600)  # a venv, its packages and a courier run of about 300 simulated s
def test_the_courier_domain_runs_without_the_recycling_package(tmp_path: Path) -> None:
    venv = tmp_path / "venv"
    made = run(sys.executable, "-m", "venv", venv, cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    pip = [venv / "bin/python", "-m", "pip", "install", "-q", "--disable-pip-version-check"]
    deps = run(*pip, "-r", REPO / "requirements.lock", cwd=tmp_path)
    assert deps.returncode == 0, deps.stderr[-3000:]
    editable = [x for p in GENERIC for x in ("-e", REPO / p)]
    ours = run(*pip, "--no-deps", *editable, cwd=tmp_path)
    assert ours.returncode == 0, ours.stderr[-3000:]
    missing = run(venv / "bin/python", "-c", "import cbdi_recycling", cwd=tmp_path)
    assert missing.returncode != 0 and "No module named 'cbdi_recycling'" in missing.stderr
    # The world service has no built-in domain: without the package, no grid world.
    grid = REPO / "domains/recycling/maps/paper-7x7.toml"
    world = run(venv / "bin/cbdi-world", "--simulator", "recycling", "--map", grid, cwd=tmp_path)
    assert world.returncode == 2
    assert "no simulator 'recycling' (installed: clock, courier)" in world.stderr

    scenario = REPO / "domains/courier/scenarios/courier.toml"
    up = [venv / "bin/cbdi", "up", scenario, "--lockstep", "--json", "--quiet"]
    done = run(*up, "--port", str(free_port()), cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout)
    assert report["result"] == "done" and report["scenario"] == "courier"
