"""Maps nobody wrote: a generated map (random walls, the bin reachable from one cell that a
person walks across) where the BDI robots recycle everything, online and offline."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from tests_support import CBDI, REPO, cbdi_up

pytestmark = pytest.mark.e2e

SEED = 1


def generated(tmp_path: Path) -> Path:
    """`cbdi map` as a user runs it: a 9x9 map with two start cells and its scenario."""
    scenario = tmp_path / f"gen-{SEED}-bdi.toml"
    argv = ["map", "--seed", str(SEED), "--agents", "2", "-o", str(tmp_path / "m.toml")]
    subprocess.run(
        [CBDI, *argv, "--scenario", str(scenario)],
        check=True,
        cwd=REPO,
    )
    return scenario


@pytest.mark.timeout(900)
@pytest.mark.parametrize(("agents", "mode"), [(2, "online"), (1, "offline")])
def test_robots_recycle_everything_on_a_generated_map(
    tmp_path: Path, agents: int, mode: str
) -> None:
    scenario = generated(tmp_path)
    args = [str(scenario), "--agents", str(agents), "--mode", mode, "--json", "--quiet"]
    result = cbdi_up(*args, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    summary = json.loads(result.stdout)
    stats = summary["stats"]
    assert summary["result"] == "done"
    assert stats["litter_on_ground"] == 0 and stats["litter_held"] == 0
    assert sum(a["recycled"] for a in stats["agents"].values()) == 4
    assert all(a["recycled"] >= 1 for a in stats["agents"].values())  # each took part
