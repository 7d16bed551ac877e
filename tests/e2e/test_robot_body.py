"""The robot-body example (docs/robot-body): three recycling robots on the paper's map,
each driven by its own process (a pymunk body under velocity control that performs
`move` and senses its place), the world simulating the rest. In lockstep the run ends
done with every item recycled, each robot's moves were its body's, and a second run
with fresh bodies is the same run (the same trace digest): what a body asks the world
from within a call is served in the call's epoch (docs/your-own-domain.md)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests_support import BIN, REPO, Proc, free_port

pytestmark = pytest.mark.e2e

EXAMPLE = REPO / "docs/robot-body"


def run_bodies(tmp_path: Path, tag: str) -> tuple[dict[str, Any], list[str]]:
    """One lockstep run of the example with three fresh bodies: its summary, their logs."""
    port = free_port()
    router = f"tcp/127.0.0.1:{port}"
    bodies = [
        Proc(
            [sys.executable, str(EXAMPLE / "body.py"), f"robot{n}", router, "--seed", str(n)],
            tmp_path / f"{tag}-body{n}.log",
        )
        for n in (1, 2, 3)
    ]
    try:
        up = subprocess.run(
            [
                *(str(BIN / "cbdi"), "up", str(EXAMPLE / "scenario.toml"), "--port", str(port)),
                *("--lockstep", "--speed", "0", "--json"),
            ],
            capture_output=True,
            text=True,
            timeout=600,
            cwd=REPO,
            stdin=subprocess.DEVNULL,
        )
        said = [b.output() for b in bodies]
    finally:
        for b in bodies:
            b.stop()
    assert up.returncode == 0, up.stderr[-3000:]
    summary: dict[str, Any] = json.loads(up.stdout)
    return summary, said


def test_three_bodies_drive_their_robots_in_lockstep(tmp_path: Path) -> None:
    summary, said = run_bodies(tmp_path, "first")
    assert summary["result"] == "done" and not summary["stalls"], summary
    assert sum(a["recycled"] for a in summary["stats"]["agents"].values()) == 3, summary
    performed = summary["performed"]
    for n, log in zip((1, 2, 3), said, strict=True):
        robot = f"robot{n}"
        assert f"{robot}: the body starts at c_" in log and "lockstep_member" in log, log[-2000:]
        assert performed[robot].get("move", 0) > 0, performed
    # The bodies asked the world to move them too: it moved each (a move a person
    # blocked is counted there as blocked, not as a move).
    counts = summary["stats"]["agents"]
    for a in counts:
        assert 0 < counts[a]["moves"] <= performed[a]["move"], counts
    again, _ = run_bodies(tmp_path, "again")
    assert again["trace_digest"] == summary["trace_digest"], (again["stats"], summary["stats"])
