"""The courier domain end to end over real Zenoh: two BDI robots deliver every parcel.

The generic services run the courier package's simulator (`--simulator courier` through
the scenario), its knowledge and agent file. On the way, a forecast repair and a clean
preemption (a low battery preempts a delivery; the executor stops after the running
drive, the robot charges, the delivery is taken up again) must happen, and the recording
passes `rerun mcap check`, converts to a rerun file and reads in `cbdi inspect`.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from cbdi.wire import decode
from cbdi.wire.agent import ArrestReport, DesireEvent
from cbdi_monitor.reader import read_messages
from tests_support import BIN, cbdi_up, free_port

pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[2]


def test_courier_robots_deliver_every_parcel(tmp_path: Path) -> None:
    rec = tmp_path / "courier.mcap"
    args = ["courier", "--lockstep", "--json", "--quiet", "--port", str(free_port())]
    done = cbdi_up(*args, "--record", str(rec), timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout)
    assert report["result"] == "done", report["reason"]
    assert report["planner"]["total"]["forecast_repairs"] >= 1
    agents = report["stats"]["agents"]
    assert sum(a["grab"] for a in agents.values()) == 3  # every parcel grabbed once

    recorded = list(read_messages(rec))
    events = [
        decode(m.payload, DesireEvent) for m in recorded if m.key.endswith("/scheduler/desires")
    ]
    arrests = [
        decode(m.payload, ArrestReport) for m in recorded if m.key.endswith("/executor/arrested")
    ]
    recharged = [e for e in events if e.desire == "recharge" and e.event == "achieved"]
    assert recharged, "no robot charged"
    # A clean preemption: the delivery's plan was arrested for the recharge, and a
    # delivery was pursued again after the robot charged.
    assert arrests, "no early arrest"
    after = min(e.time for e in recharged)
    assert any(
        e.desire == "deliver" and e.event == "activated" and e.time >= after for e in events
    ), "no delivery taken up again after charging"
    delivered = {
        g[1] for e in events if e.desire == "deliver" and e.event == "achieved" for g in e.goal
    }
    assert delivered <= {"p1", "p2", "p3"}

    check = subprocess.run(
        [str(BIN / "rerun"), "mcap", "check", str(rec)], capture_output=True, text=True
    )
    assert check.returncode == 0, check.stdout + check.stderr
    rrd = tmp_path / "courier.rrd"  # the rerun view of it
    view = subprocess.run(
        [str(BIN / "cbdi"), "view", str(rec), "--rrd", str(rrd)], capture_output=True, text=True
    )
    assert view.returncode == 0, view.stderr
    verify = subprocess.run(
        [str(BIN / "rerun"), "rrd", "verify", str(rrd)], capture_output=True, text=True
    )
    assert verify.returncode == 0, verify.stdout + verify.stderr
    inspect = subprocess.run(
        [str(BIN / "cbdi"), "inspect", str(rec)], capture_output=True, text=True
    )
    assert inspect.returncode == 0, inspect.stderr
    assert "result: done" in inspect.stdout


def test_work_that_comes_back_goes_to_the_robot_nearer_then(tmp_path: Path) -> None:
    """courier-rounds: two parcels cross the floor in opposite directions, each twice.
    Each robot starts beside one and takes it; once both are delivered each robot stands
    near the other's start. A claim ends when its goal is achieved, so when the parcels
    come back the robots claim them afresh and the nearer one takes each: every robot
    delivers both parcels once (with claims that outlived their goal, each robot walked
    back for its first parcel)."""
    rec = tmp_path / "rounds.mcap"
    args = ["courier-rounds", "--lockstep", "--json", "--quiet", "--port", str(free_port())]
    done = cbdi_up(*args, "--record", str(rec), timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout)
    assert report["result"] == "done", report["reason"]
    assert report["stats"]["delivered"] == report["stats"]["deliveries"] == 4
    achieved: dict[str, list[str]] = {}
    for m in read_messages(rec):
        if m.key.endswith("/scheduler/desires"):
            e = decode(m.payload, DesireEvent)
            if e.desire == "deliver" and e.event == "achieved":
                achieved.setdefault(e.agent, []).extend(g[1] for g in e.goal)
    assert achieved == {"robot1": ["p1", "p2"], "robot2": ["p2", "p1"]}, achieved


def _pair(tmp_path: Path, together: bool) -> tuple[dict[str, object], list[DesireEvent]]:
    """courier-pair in lockstep, its agent file as shipped or without `together`."""
    scenario = ROOT / "domains/courier/scenarios/courier-pair.toml"
    if not together:
        agents = ROOT / "domains/courier/agents"
        text = (agents / "courier-jobs.toml").read_text().replace(', together = "deliveries"', "")
        text = text.replace('"../pddl/domain.pddl"', f'"{agents.parent / "pddl/domain.pddl"}"')
        (tmp_path / "alone.toml").write_text(text)
        body = scenario.read_text().replace("../agents/courier-jobs.toml", "alone.toml")
        body = body.replace("../maps/", f"{agents.parent / 'maps'}/")
        scenario = tmp_path / "courier-alone.toml"
        scenario.write_text(body)
    rec = tmp_path / f"pair-{together}.mcap"
    args = [str(scenario), "--lockstep", "--json", "--quiet", "--port", str(free_port())]
    done = cbdi_up(*args, "--record", str(rec), timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout)
    assert report["result"] == "done", report["reason"]
    events = [
        decode(m.payload, DesireEvent)
        for m in read_messages(rec)
        if m.key.endswith("/scheduler/desires")
    ]
    return report, events


def test_two_jobs_pursued_together_take_one_round_trip(tmp_path: Path) -> None:
    """courier-pair: p2 waits in the west for the east, p1 in the east for the west, the
    robot starts in the west and carries one parcel at a time. Its two desires pursued
    together are one goal, so one plan does p2 east then p1 west (11 drives: 1 + 5 + 5);
    pursued one at a time, p1 (its name first) sends the robot east empty and p2 makes it
    drive east again (18)."""
    joint, events = _pair(tmp_path, together=True)
    drives = joint["stats"]["agents"]["robot1"]["drive"]  # type: ignore[index]
    assert drives == 11, drives
    assert [(e.desire, e.event) for e in events if e.event in ("activated", "achieved")] == [
        ("deliveries", "activated"),
        ("deliver_p2", "achieved"),
        ("deliver_p1", "achieved"),
        ("deliveries", "achieved"),
    ]
    alone, _ = _pair(tmp_path, together=False)
    assert alone["stats"]["agents"]["robot1"]["drive"] > drives + 4  # type: ignore[index]
