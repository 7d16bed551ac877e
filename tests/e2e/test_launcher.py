"""`cbdi up`: the launcher runs scenarios as processes, restarts crashed services, reports."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests_support import CBDI, REPO, cbdi_up, wait_for

pytestmark = pytest.mark.e2e

up = cbdi_up


def test_corridor_run_ends_done_with_json_summary() -> None:
    result = up("corridor", "--json", "--quiet")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["result"] == "done"
    robot = summary["stats"]["agents"]["robot1"]
    assert (robot["moves"], robot["pickups"], robot["recycled"]) == (6, 1, 1)
    assert summary["restarts"] == {"router": 0, "world": 0, "robot1/executor": 0}
    assert summary["planner"]["agents"] == {}  # a scripted robot has no planner
    assert summary["planner"]["total"]["replans"] == 0
    assert set(summary["freezes"]) == set(summary["freeze_kills"]) == set(summary["restarts"])
    memory = summary["memory"]  # three Python processes hold tens of MB each, at least
    assert memory["samples"] >= 1 and memory["peak_total_mb"] > 30
    assert set(memory["peak_mb"]) <= set(summary["restarts"])


def test_several_agents_share_one_world() -> None:
    result = up("paper-7x7-scripted", "--agents", "3", "--speed", "40", "--json", "--quiet")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    agents = summary["stats"]["agents"]
    assert sorted(agents) == ["robot1", "robot2", "robot3"]
    assert sum(a["recycled"] for a in agents.values()) == 3
    assert summary["stats"]["litter_on_ground"] == 0


def test_bdi_agent_recycles_everything_in_the_paper_scenario(tmp_path: Path) -> None:
    """Planner, scheduler and executor processes: the agent senses the litter, takes up the
    desire, plans continually, executes and recycles all three items; a person walking
    onto a cell of its plan is foreseen and the plan repaired before the move fails."""
    rec = tmp_path / "bdi.mcap"
    result = up("paper-7x7", "--speed", "10", "--json", "--quiet", "--record", str(rec))
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["result"] == "done"
    robot = summary["stats"]["agents"]["robot1"]
    assert robot["recycled"] == 3 and robot["pickups"] == 3
    assert robot["moves"] >= 22  # the paper: 22 moves is the shortest tour
    acted = summary["actions"]["robot1"]  # from the world's request trace, counted live
    assert acted["actions"] >= robot["moves"] + robot["pickups"] + robot["recycled"]
    assert 0 <= acted["first_action"] < summary["sim_time"]
    assert set(summary["restarts"]) >= {"robot1/planner", "robot1/scheduler", "robot1/executor"}
    assert not any(summary["restarts"].values())
    planner = summary["planner"]["agents"]["robot1"]  # counted live from the planner's keys
    for name in ("plans", "replans", "forecast_repairs", "improvements", "search_rounds"):
        assert isinstance(planner[name], int) and planner[name] >= 0, name
        assert summary["planner"]["total"][name] == planner[name]
    assert planner["search_rounds"] > 0 and planner["plans"] >= 1
    assert planner["replans"] == sum(planner["replans_by"].values())
    assert planner["forecast_repairs"] == planner["replans_by"]["repair"]
    assert_repaired_before_failure(rec)


def assert_repaired_before_failure(rec: Path) -> None:
    """The planner forecast the executing plan; every repair it published followed a
    forecast that a step after the committed part would fail, and continues after that
    committed step. (Whether a person crosses the plan in a given run depends on timing:
    tests/e2e/test_planner_service.py stages that case deterministically.)"""
    from cbdi.wire import decode
    from cbdi.wire.agent import PartialPlan
    from cbdi.wire.planner import ForecastReport
    from cbdi_monitor.reader import read_messages

    recorded = list(read_messages(rec))
    forecasts = [
        (m.log_ns, decode(m.payload, ForecastReport))
        for m in recorded
        if m.key == "cbdi/robot1/planner/forecasts"
    ]
    plans = [
        (m.log_ns, decode(m.payload, PartialPlan))
        for m in recorded
        if m.key == "cbdi/robot1/planner/plans"
    ]
    rounds = [m for m in recorded if m.key == "cbdi/robot1/planner/rounds"]
    assert forecasts and rounds
    repairs = [
        (t, p.applies_after)
        for t, p in plans
        if p.baseline != p.plan_id
        and p.applies_after
        and any(r.purpose == "repair" and r.plan_id == p.plan_id for r in _rounds(rounds))
    ]
    for t, after in repairs:
        assert any(
            f.kind == "fails_after_committed" and f.committed == after and tf <= t
            for tf, f in forecasts
        ), (after, [f for _, f in forecasts])


def _rounds(recorded: list) -> list:
    from cbdi.wire import decode
    from cbdi.wire.planner import SearchRound

    return [decode(m.payload, SearchRound) for m in recorded]


def test_time_limited_run_and_seconds_until() -> None:
    result = up("paper-7x7-scripted", "--until", "5", "--speed", "20", "--json", "--quiet")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["result"] == "time_limit" and summary["epochs"] == 5


def test_a_run_shorter_than_the_start_ends_when_the_world_does() -> None:
    # Three BDI agents, one epoch, one service late beyond the world's 30 s start
    # barrier (as on a loaded machine): the world runs without it and finishes before
    # the launcher has seen every service alive. The launcher still hears the world's
    # last word and ends (it used to wait for its 120 s limit and exit 1).
    started = time.monotonic()
    late = ("--delay", "robot3/executor=35")
    result = up("paper-7x7", "--agents", "3", "--until", "1", *late, "--json", "--quiet")
    assert result.returncode == 0, result.stderr[-2000:]
    summary = json.loads(result.stdout)
    assert summary["result"] == "time_limit" and summary["epochs"] == 1
    assert time.monotonic() - started < 100


def test_unknown_scenario_and_bad_options_exit_2() -> None:
    result = up("no-such-scenario")
    assert result.returncode == 2 and "no such scenario" in result.stderr
    assert "paper-7x7" in result.stderr  # it lists the ones it knows
    result = up("corridor", "--until", "soon")
    assert result.returncode == 2 and "--until" in result.stderr


def _start_and_kill_agent(tmp_path: Path, *extra: str) -> tuple[subprocess.Popen[str], Path]:
    log = tmp_path / "up.log"
    proc = subprocess.Popen(
        [CBDI, "up", "paper-7x7-scripted", "--speed", "6", "--json", *extra],
        stdout=subprocess.PIPE,
        stderr=log.open("w"),
        text=True,
        cwd=REPO,
        stdin=subprocess.DEVNULL,
    )
    pattern = re.compile(r"started service=robot1/executor pid=(\d+)")
    wait_for(
        lambda: pattern.search(log.read_text()) and "event=requested" in log.read_text(),
        timeout=60,
        what="the agent to start acting",
    )
    match = pattern.search(log.read_text())
    assert match
    os.kill(int(match.group(1)), signal.SIGKILL)
    return proc, log


def test_killed_service_is_restarted_and_the_run_completes(tmp_path: Path) -> None:
    proc, log = _start_and_kill_agent(tmp_path)
    out, _ = proc.communicate(timeout=120)
    text = log.read_text()
    assert "restarting service=robot1/executor exit_code=-9 restart=1" in text
    assert len(re.findall(r"started service=robot1/executor pid=", text)) == 2
    summary = json.loads(out)
    assert proc.returncode == 0, text[-3000:]
    assert summary["result"] == "done" and summary["restarts"]["robot1/executor"] == 1
    assert summary["stats"]["litter_recycled"] == 3


def test_restart_policy_never_fails_the_run(tmp_path: Path) -> None:
    proc, log = _start_and_kill_agent(tmp_path, "--restart", "never")
    out, _ = proc.communicate(timeout=60)
    summary = json.loads(out)
    assert proc.returncode == 1
    assert summary["result"] == "failed" and "robot1/executor" in summary["reason"]
    assert "gave_up service=robot1/executor" in log.read_text()


def test_ctrl_c_stops_everything(tmp_path: Path) -> None:
    log = tmp_path / "up.log"
    proc = subprocess.Popen(
        [CBDI, "up", "paper-7x7-scripted", "--speed", "1", "--json"],
        stdout=subprocess.PIPE,
        stderr=log.open("w"),
        text=True,
        cwd=REPO,
        stdin=subprocess.DEVNULL,
    )
    wait_for(lambda: "event=requested" in log.read_text(), timeout=60, what="run to start")
    pids = [int(p) for p in re.findall(r"pid=(\d+)", log.read_text())]
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=60)
    assert json.loads(out)["result"] == "interrupted" and proc.returncode == 130
    for pid in pids:  # no child left behind
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_broken_map_is_refused_before_the_run_with_the_map_error(tmp_path: Path) -> None:
    bad_map = tmp_path / "bad.toml"
    bad_map.write_text('name = "bad"\ngrid = """\nBA.\n.x.\n"""\n')
    scenario = tmp_path / "scenario.toml"
    scenario.write_text(
        f'name = "bad"\nmap = "{bad_map}"\n[run]\nsimulator = "recycling"\n'
        '[[agents]]\nname = "robot1"\n'
    )
    result = up(str(scenario), "--json", "--quiet", timeout=60)
    # The world is built before anything starts (tests/shared/test_preflight.py).
    assert result.returncode == 2 and not result.stdout, result.stderr[-2000:]
    assert "grid row 1 column 1: unknown cell 'x'" in result.stderr


def test_paper_situation_flags_reach_the_world_and_the_agent(tmp_path: Path) -> None:
    rec = tmp_path / "k2.mcap"
    result = up(
        "paper-7x7",
        "--speed",
        "40",
        "--option",
        "move_step=8",
        "--option",
        "det_area=2",
        "--option",
        "known_litter=2",
        "--option",  # the scenario's jitter off: steps exactly every move_step
        "people_jitter=0",
        "--json",
        "--quiet",
        "--record",
        str(rec),
    )
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["stats"]["litter_recycled"] == 3  # the third one found
    from cbdi_recycling.wire import Percepts, grid_map

    from cbdi.wire import decode
    from cbdi.wire.world import WorldInfo
    from cbdi_monitor.reader import read_messages

    info = next(decode(m.payload, WorldInfo) for m in read_messages(rec, ["cbdi/world/info"]))
    assert grid_map(info).detection_depth == {"robot1": 2}
    first = next(
        decode(m.payload, Percepts) for m in read_messages(rec, ["cbdi/world/percepts/robot1"])
    )
    assert first.depth == 2
    from cbdi.wire.world import WorldSnapshot

    people = [
        [tuple(p.cell) for p in decode(m.payload, WorldSnapshot).people]
        for m in read_messages(rec, ["cbdi/world/snapshot"])
    ][:17]
    person1 = [cells[0] for cells in people]
    moves_at = [i for i in range(1, len(person1)) if person1[i] != person1[i - 1]]
    assert moves_at[:2] == [8, 16]  # one step every 8 epochs
    # The scenario's people_phase: the world started people where seed 1 puts them.
    from cbdi_recycling.chance import Chance
    from cbdi_recycling.maps import load_map
    from cbdi_recycling.world import AgentSpec, World

    paper = load_map(REPO / "domains/recycling/maps/paper-7x7.toml")
    phased = World(paper, [AgentSpec("robot1", (0, 1))], seed=1, chance=Chance(people_phase=True))
    assert people[0] == [p.cell for p in phased.people]
    assert people[0] != [p.path[0] for p in paper.people]  # seed 1 moves person2


def test_bdi_agent_plans_then_acts_in_offline_mode() -> None:
    """`--mode offline`: the paper's baseline, a complete plan before acting, no rounds."""
    result = up("paper-7x7", "--mode", "offline", "--speed", "20", "--json", "--quiet")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["result"] == "done"
    assert summary["stats"]["agents"]["robot1"]["recycled"] == 3
    planner = summary["planner"]["agents"]["robot1"]
    assert planner["plans"] >= 1 and planner["search_rounds"] == 0
    assert planner["forecast_repairs"] == 0


def test_a_taken_router_port_fails_the_run_instead_of_joining_another(tmp_path: Path) -> None:
    """Another run's router on our port: its `alive` token must not pass for ours, or our
    world and robots would join that run (seen with parallel benchmark runs)."""
    from tests_support import Proc, free_port

    port = free_port()
    other = Proc([str(CBDI), "router", "--listen", f"tcp/127.0.0.1:{port}"], tmp_path / "r.log")
    try:
        wait_for(lambda: "event=ready" in other.output(), what="the other router")
        result = cbdi_up("corridor", "--port", str(port), "--json", "--quiet", "--restart", "never")
    finally:
        other.stop()
    assert result.returncode == 1
    summary = json.loads(result.stdout)
    assert summary["result"] == "failed" and "could not listen" in summary["reason"]
    assert not summary["stats"]  # nothing ran on the other router
