"""`cbdi replay FILE --agent robot1 --check` on a real recording (issue 12).

A lockstep `cbdi up paper-7x7` run is recorded; its robot's planner and scheduler, rebuilt
in one process and fed the recorded inputs, publish the same messages. A copy of the file
with one input changed makes them decide otherwise, and the check names the first message
that differs.
"""

from __future__ import annotations

import re
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgpack
import pytest

from cbdi_monitor.reader import read_messages
from cbdi_monitor.recorder import McapRecorder
from tests_support import CBDI, REPO, cbdi_up

# A changed input makes the replay wait out its 60 s stall limit where the agent decides
# otherwise; on a loaded machine that and the replay pass the suite's 120 s.
pytestmark = [pytest.mark.e2e, pytest.mark.timeout(400)]

Change = Callable[[str, dict[str, Any]], bool]  # alter the message in place, say if it did


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("replay") / "paper.mcap"
    result = cbdi_up("paper-7x7", "--speed", "0", "--json", "--quiet", "--record", str(path))
    assert result.returncode == 0, result.stderr[-3000:]
    return path


def check(path: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    argv = [CBDI, "replay", str(path), "--agent", "robot1", "--check", *extra]
    return subprocess.run(
        argv, capture_output=True, text=True, timeout=300, cwd=REPO, stdin=subprocess.DEVNULL
    )


def altered(src: Path, dst: Path, change: Change) -> dict[str, Any]:
    """Copy `src` to `dst` with the first message `change` alters; return it as changed."""
    rec = McapRecorder(dst)
    changed: dict[str, Any] = {}
    for m in read_messages(src):
        payload = m.payload
        if not changed and m.schema != "cbdi.Liveliness/1":
            msg = msgpack.unpackb(m.payload)
            if isinstance(msg, dict) and change(m.key, msg):
                changed, payload = msg, msgpack.packb(msg)
        rec.write(m.key, payload, m.log_ns, m.publish_ns, m.seq)
    rec.close()
    assert changed, "nothing in the recording to change"
    return changed


def test_the_replayed_planner_and_scheduler_decide_as_recorded(recording: Path) -> None:
    result = check(recording)
    assert result.returncode == 0, result.stdout + result.stderr[-3000:]
    found = re.search(r"same: (\d+) messages of robot1's planner and scheduler", result.stdout)
    assert found and int(found.group(1)) > 200, result.stdout
    assert "as the launcher recorded it" in result.stdout  # the agent file it was given


def test_a_percept_without_its_litter_changes_the_beliefs_of_that_epoch(
    recording: Path, tmp_path: Path
) -> None:
    def drop_litter(key: str, msg: dict[str, Any]) -> bool:
        if key != "cbdi/world/percepts/robot1" or msg["epoch"] < 20 or not msg["items"]:
            return False
        msg["gone"] = msg["items"].pop(0)["name"]
        return True

    changed = altered(recording, tmp_path / "litter.mcap", drop_litter)
    result = check(tmp_path / "litter.mcap")
    assert result.returncode == 1, result.stdout + result.stderr[-3000:]
    head = next(line for line in result.stdout.splitlines() if "first difference" in line)
    assert "cbdi/robot1/scheduler/beliefs" in head
    assert f"epoch {changed['epoch']}," in head and "stage beliefs" in head
    assert changed["gone"] in result.stdout  # the belief in the item's place is named


def test_a_step_that_failed_instead_changes_what_the_agent_does_next(
    recording: Path, tmp_path: Path
) -> None:
    def fail(key: str, msg: dict[str, Any]) -> bool:
        if key != "cbdi/robot1/executor/status" or msg["status"] != "succeeded":
            return False
        if msg["time"] < 40:
            return False
        msg["status"], msg["reason"] = "failed", "changed by the test"
        return True

    changed = altered(recording, tmp_path / "failed.mcap", fail)
    result = check(tmp_path / "failed.mcap")
    assert result.returncode == 1, result.stdout + result.stderr[-3000:]
    head = re.search(r"first difference: (cbdi/robot1/\S+) #\d+ .*?, epoch (\d+)", result.stdout)
    assert head, result.stdout
    # The executor's reports of epoch k reach the scheduler in epoch k + 1.
    assert int(changed["time"]) < int(head.group(2)) <= int(changed["time"]) + 2
    assert re.search(r"differs: \d+ messages", result.stdout)


def test_the_agent_file_can_be_given_instead(recording: Path) -> None:
    agent_file = str(REPO / "domains/recycling/agents/recycler.toml")
    result = check(recording, "--agent-file", agent_file)
    assert result.returncode == 0, result.stdout + result.stderr[-3000:]
    assert "with --agent-file's file" in result.stdout
