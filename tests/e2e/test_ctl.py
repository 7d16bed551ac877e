"""The operator's command line against a running agent (real Zenoh, real processes):
a desire added with `cbdi ctl` is pursued, one removed is dropped, a refused one says
why, and `show` tells the intention and its plan."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from cbdi import keys
from cbdi.wire import decode
from cbdi.wire.agent import ActionStatus, ArrestReport, DesireEvent
from cbdi_monitor.reader import read_messages
from tests_support import BIN, Proc, free_port, wait_for

pytestmark = pytest.mark.e2e


def ctl(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    argv = [str(BIN / "cbdi"), "ctl", *args, "--connect", endpoint, "--timeout", "20"]
    return subprocess.run(argv, capture_output=True, text=True, timeout=60, check=False)


def now(endpoint: str) -> float:
    """robot1's scheduler's simulated time (-1 if it does not answer now)."""
    shown = ctl(endpoint, "show", "robot1", "--no-beliefs", "--json")
    return float(json.loads(shown.stdout)["time"]) if shown.returncode == 0 else -1.0


@pytest.mark.timeout(600)
def test_an_operator_adds_removes_and_is_refused(tmp_path: Path) -> None:
    port, rec = free_port(), tmp_path / "ctl.mcap"
    endpoint = f"tcp/127.0.0.1:{port}"
    argv = [str(BIN / "cbdi"), "up", "paper-7x7", "--port", str(port), "--json", "--quiet"]
    # Speed 0.5: the robot pursues the operator's desire for several wall seconds, long
    # enough for `cbdi ctl` (a process per call, seconds each on a loaded machine) to
    # see it and stop it there.
    launcher = Proc([*argv, "--speed", "0.5", "--record", str(rec)], tmp_path / "up.log")
    try:
        wait_for(
            lambda: "started service=robot1/executor" in launcher.output(),
            timeout=60,
            what="the run to start",
        )
        wait_for(
            lambda: ctl(endpoint, "show", "robot1", "--no-beliefs").returncode == 0,
            timeout=60,
            what="robot1's scheduler to answer",
        )
        # (0, 6) is off the people's loops: nobody stands on the goal for long.
        visit = ctl(
            endpoint,
            "desire",
            "add",
            "robot1",
            "visit",
            "(in {self} c_0_6)",
            "--priority",
            "0.95",
            "--deadline",
            "300",
            "--context",
            "(map_loaded)",
        )
        assert visit.returncode == 0 and "accepted" in visit.stdout, visit.stderr
        later = ctl(endpoint, "desire", "add", "robot1", "later", "(in robot1 c_6_6)")
        assert later.returncode == 0, later.stderr
        assert ctl(endpoint, "desire", "check", "robot1", "later").stdout.strip() == "holds"
        removed = ctl(endpoint, "desire", "remove", "robot1", "later")
        assert removed.returncode == 0, removed.stderr

        stranger = ctl(endpoint, "--group", "strangers", "belief", "add", "robot1", "(map_loaded)")
        assert stranger.returncode == 1 and "group 'strangers' is not allowed" in stranger.stderr
        typo = ctl(endpoint, "desire", "add", "robot1", "typo", "(inn robot1 c_0_6)")
        assert typo.returncode == 1 and "'inn' is not declared by the domain" in typo.stderr
        ghost = ctl(endpoint, "desire", "remove", "robot1", "ghost")
        assert ghost.returncode == 1 and "no desire 'ghost'" in ghost.stderr

        def pursuing() -> bool:
            shown = ctl(endpoint, "show", "robot1", "--no-beliefs", "--json")
            state = json.loads(shown.stdout) if shown.returncode == 0 else {}
            intention = state.get("intention") or {}
            return intention.get("desire") == "visit" and bool(intention.get("steps"))

        wait_for(pursuing, timeout=120, what="robot1 to pursue the operator's desire")
        text = ctl(endpoint, "show", "robot1")
        assert text.returncode == 0 and "intention: visit (plan " in text.stdout
        assert "(move robot1 " in text.stdout and "beliefs (" in text.stdout

        stop = ctl(endpoint, "stop", "--all", "--wait", "60")
        assert stop.returncode == 0 and "robot1 stopped at t=" in stop.stdout, stop.stderr
        shown = json.loads(ctl(endpoint, "show", "robot1", "--no-beliefs", "--json").stdout)
        # The visit, or (a loaded machine's ctl calls came late) the recycling after it.
        assert shown["halted"] and shown["intention"] is not None, shown
        stopped = shown["intention"]["desire"]
        # Stopped for 5 simulated seconds (however long that takes the loaded machine's
        # lockstep world): nothing may start meanwhile.
        wait_for(lambda: now(endpoint) >= shown["time"] + 5.0, timeout=180, what="5 s stopped")
        assert ctl(endpoint, "resume", "robot1").returncode == 0
        wait_for(lambda: not launcher.alive(), timeout=400, what="the run to end")
    finally:
        code = launcher.stop()
    assert code == 0, launcher.output()[-3000:]  # all litter recycled, as asked

    recorded = list(read_messages(rec))

    def of(key: str, cls: type) -> list:
        return [decode(m.payload, cls) for m in recorded if m.key == key]

    events = of(keys.scheduler_desires("robot1"), DesireEvent)
    ends = ("added", "activated", "achieved", "dropped")  # "waiting": a person passed by
    visit_events = [e.event for e in events if e.desire == "visit" and e.event in ends]
    assert visit_events[:3] == ["added", "activated", "achieved"], visit_events
    later_events = [(e.event, e.reason) for e in events if e.desire == "later"]
    assert later_events == [("added", ""), ("dropped", "removed by operator")], later_events
    assert not [e for e in events if e.desire in ("typo", "ghost")]

    # The safe stop: the step running at the stop ended (a 3 s pickup at most), and no
    # step started until the resume.
    halted = next(e.time for e in events if e.desire == stopped and e.event == "halted")
    resumed = next(e.time for e in events if e.desire == stopped and e.event == "resumed")
    still = min(
        r.time for r in of(keys.executor_arrested("robot1"), ArrestReport) if r.time >= halted
    )
    assert halted <= still <= halted + 4 < resumed
    started = [
        s.time
        for s in of(keys.executor_status("robot1"), ActionStatus)
        if s.status == "running" and still < s.time < resumed
    ]
    assert not started, started
