"""SIGTERM to `cbdi view FILE --web` ends the rerun viewer it started (issue 15)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from cbdi.wire import encode
from cbdi.wire.world import Tick
from cbdi_monitor.recorder import McapRecorder
from tests_support import free_port, wait_for

CBDI = Path(sys.executable).parent / "cbdi"


def children(pid: int) -> list[int]:
    """Every live descendant of `pid` (from /proc)."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            fields = stat.rsplit(")", 1)[1].split()
            if fields[0] != "Z":
                parents[int(entry.name)] = int(fields[1])
    found, todo = [], [pid]
    while todo:
        p = todo.pop()
        kids = [c for c, parent in parents.items() if parent == p]
        found += kids
        todo += kids
    return found


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_sigterm_to_view_web_ends_the_viewer(tmp_path: Path) -> None:
    rec = McapRecorder(tmp_path / "r.mcap")
    for i in range(3):
        tick = Tick(epoch=i, time=float(i), epoch_duration=1.0, speed=1.0, lockstep=False)
        rec.write("cbdi/world/clock", encode(tick), log_ns=(i + 1) * 10**9)
    rec.close()
    log = (tmp_path / "view.log").open("w")
    view = subprocess.Popen(
        [str(CBDI), "view", str(tmp_path / "r.mcap"), "--web", "--web-port", str(free_port())],
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    viewer: list[int] = []
    try:
        wait_for(lambda: bool(children(view.pid)), what="the rerun viewer", timeout=60)
        time.sleep(1.0)  # the viewer is up (or still starting): either way it must go
        viewer = children(view.pid)  # the rerun script and the binary it starts
        view.send_signal(signal.SIGTERM)
        assert view.wait(30) == 128 + signal.SIGTERM
        wait_for(lambda: not any(alive(p) for p in viewer), what="the viewer's end", timeout=15)
    finally:
        if view.poll() is None:
            os.killpg(view.pid, signal.SIGKILL)
        for pid in viewer:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
        log.close()
