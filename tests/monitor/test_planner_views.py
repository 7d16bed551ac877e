"""What the monitor makes of the planner's messages: `cbdi inspect` counts, the rerun
entities (plots, decisions in the text log, the committed part of the route drawn apart)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from cbdi import keys
from cbdi.wire import encode
from cbdi.wire.agent import ActionStatus, PartialPlan, PlanStep
from cbdi.wire.base import Message
from cbdi.wire.planner import ForecastReport, SearchRequest, SearchRound
from cbdi.wire.world import ActionOutcome
from cbdi_monitor.inspect import inspect_messages, render
from cbdi_monitor.reader import RecordedMessage, read_messages
from cbdi_monitor.recorder import McapRecorder
from cbdi_monitor.rerun_log import RerunLogger
from cbdi_monitor.schemas import peek_schema

A = "robot1"


def move(plan_id: str, n: int, to: tuple[int, int]) -> PlanStep:
    return PlanStep(
        step_id=f"{plan_id}-{n}",
        action="move",
        args=[A, "c_0_0", f"c_{to[0]}_{to[1]}"],
        start=float(n),
        duration=1.0,
    )


def plan(plan_id: str, cells: list[tuple[int, int]], after: str = "") -> PartialPlan:
    steps = [move(plan_id, i + 1, c) for i, c in enumerate(cells)]
    return PartialPlan(agent=A, plan_id=plan_id, baseline=after, steps=steps, applies_after=after)


def rnd(plan_id: str, purpose: str, mode: str = "G", number: int = 1) -> SearchRound:
    return SearchRound(
        agent=A,
        request_id="s1",
        plan_id=plan_id,
        purpose=purpose,
        number=number,
        kind="best",
        mode=mode,
        expanded=40,
        seconds=0.01,
        best_h=4,
        plan_actions=3,
        time=1.0,
    )


def forecast(kind: str, plan_id: str, committed: str, failed: str = "") -> ForecastReport:
    return ForecastReport(
        agent=A,
        plan_id=plan_id,
        kind=kind,
        failed_step=failed,
        reason="a person is in the way" if failed else "",
        committed=committed,
        time=2.0,
    )


def status(step_id: str, what: str) -> ActionStatus:
    plan_id = step_id.rsplit("-", 1)[0]
    return ActionStatus(
        agent=A, plan_id=plan_id, step_id=step_id, action="move", status=what, reason="", time=1.0
    )


def session() -> list[tuple[str, Message]]:
    """A search, a plan, a failure forecast after the committed steps, a repair."""
    return [
        (keys.planner_requests(A), SearchRequest(agent=A, request_id="s1", kind="start")),
        (keys.planner_rounds(A), rnd("p1", "new")),
        (keys.planner_plans(A), plan("p1", [(1, 0), (2, 0), (3, 0), (4, 0)])),
        (keys.scheduler_plans(A), plan("p1", [(1, 0), (2, 0), (3, 0), (4, 0)])),
        (keys.executor_status(A), status("p1-1", "running")),
        (keys.planner_forecasts(A), forecast("holds", "p1", "p1-2")),
        (keys.planner_forecasts(A), forecast("fails_after_committed", "p1", "p1-2", "p1-3")),
        (keys.planner_rounds(A), rnd("p2", "repair")),
        (keys.planner_rounds(A), rnd("p2", "repair", mode="NG", number=2)),  # fell back
        (keys.planner_plans(A), plan("p2", [(2, 1), (3, 1)], after="p1-2")),
    ]


class FakeRerun:
    """Stands in for the rerun module and a recording stream: remembers what is logged."""

    def __init__(self) -> None:
        self.logged: list[tuple[str, str, Any]] = []

    def __getattr__(self, archetype: str) -> Any:
        return lambda *args, **kw: (archetype, args, kw)

    def log(self, path: str, entity: Any, static: bool = False) -> None:
        self.logged.append((path, entity[0], entity))

    def set_time(self, *args: Any, **kw: Any) -> None:
        pass

    def last(self, path: str) -> Any:
        return next(e for p, _, e in reversed(self.logged) if p == path)

    def texts(self) -> list[str]:
        return [e[1][0] for p, kind, e in self.logged if kind == "TextLog" and "/log" in p]


def recorded(messages: list[tuple[str, Message]]) -> list[RecordedMessage]:
    out = []
    for i, (key, msg) in enumerate(messages, 1):
        payload = encode(msg)
        out.append(RecordedMessage(key, payload, i, i, i, peek_schema(payload), "msgpack"))
    return out


def test_inspect_counts_replans_repairs_rounds_and_forecasts() -> None:
    report = inspect_messages(recorded(session()))
    robot = report.agents[A]
    assert (robot.replans, robot.forecast_repairs, robot.improvements) == (1, 1, 0)
    assert (robot.plans_published, robot.search_rounds, robot.search_expanded) == (2, 3, 120)
    assert robot.replans_by == {"new": 0, "repair": 1, "revise": 0, "improve": 0}
    assert robot.forecasts == {"fails_in_committed": 0, "fails_after_committed": 1, "holds": 1}
    assert robot.plans == 1  # passed to the executor (the scheduler's key)
    assert "planner: plans=2 replans=1 (repair=1) forecast_repairs=1" in render(report)


def test_inspect_leaves_planner_counts_null_without_a_planner() -> None:
    moved = ActionOutcome(
        agent=A, request_id="1", action="move", status="succeeded", reason="", epoch=1, time=1.0
    )
    report = inspect_messages(recorded([(keys.world_outcomes(A), moved)]))
    assert report.agents[A].actions == {"move:succeeded": 1}
    assert report.agents[A].counters == {}  # no world info recorded: no domain's counters
    assert report.agents[A].replans is None and report.agents[A].search_rounds is None


def test_rerun_plots_rounds_replans_and_forecasts_and_logs_decisions() -> None:
    fake = FakeRerun()
    logger = RerunLogger(fake, fake)
    logger.cells[A] = (0, 0)
    for m in recorded(session()):
        logger.handle(m)
    assert logger.skipped == 0
    paths = {p for p, _, _ in fake.logged}
    for name in ("expanded", "best_h", "round_seconds", "search_rounds", "replans", "plan_steps"):
        assert f"plots/{A}/planner/{name}" in paths
    assert fake.last(f"plots/{A}/planner/replans")[1] == (1,)
    assert fake.last(f"plots/{A}/planner/forecast_repairs")[1] == (1,)
    assert fake.last(f"plots/{A}/forecasts/fails_after_committed")[1] == (1,)
    assert fake.last(f"plots/{A}/forecasts/fails_in_committed")[1] == (0,)
    texts = fake.texts()
    assert "planner: plan p1 (new): 4 steps" in texts
    assert "planner: replan #1 p2 (repair, after p1-2): 2 steps" in texts
    assert any(t.startswith("forecast: p1 fails_after_committed at p1-3") for t in texts)
    assert any("repair search for p2 falls back from G to NG (round 2)" in t for t in texts)


def test_rerun_draws_the_committed_route_apart_from_the_rest() -> None:
    fake = FakeRerun()
    logger = RerunLogger(fake, fake)
    logger.cells[A] = (0, 0)
    messages = session()
    for m in recorded(messages[:6]):  # p1 running its first step, committed through p1-2
        logger.handle(m)
    firm = fake.last(f"world/plans/{A}/committed")[1][0][0]
    loose = fake.last(f"world/plans/{A}/rest")[1][0][0]
    assert firm == [(0.5, 0.5), (1.5, 0.5), (2.5, 0.5)]
    assert loose == [(2.5, 0.5), (3.5, 0.5), (4.5, 0.5)]
    for m in recorded(messages[6:]):  # the repair takes over after p1-2
        logger.handle(m)
    assert fake.last(f"world/plans/{A}/committed")[1][0][0] == firm
    assert fake.last(f"world/plans/{A}/rest")[1][0][0] == [(2.5, 0.5), (2.5, 1.5), (3.5, 1.5)]
    late = (keys.scheduler_plans(A), plan("p1", [(1, 0), (2, 0), (3, 0), (4, 0)]))
    ended = (keys.executor_status(A), status("p1-1", "succeeded"))
    for m in recorded([late, ended]):  # a replaced plan passed on late changes nothing
        logger.handle(m)
    assert fake.last(f"world/plans/{A}/committed")[1][0][0] == [(0.5, 0.5), (2.5, 0.5)]
    assert logger.routes[A].plan_id == "p2"


@pytest.mark.skipif(
    shutil.which("rerun", path=str(Path(sys.executable).parent)) is None,
    reason="rerun-sdk is not installed",
)
def test_rrd_of_a_planning_run_verifies_and_holds_the_planner_entities(tmp_path: Path) -> None:
    from cbdi_monitor.view import convert

    mcap, rrd = tmp_path / "run.mcap", tmp_path / "run.rrd"
    rec = McapRecorder(mcap)
    for i, (key, msg) in enumerate(session(), 1):
        rec.write(key, encode(msg), log_ns=i * 1_000_000_000)
    rec.close()
    assert convert(mcap, rrd) == len(list(read_messages(mcap)))
    rerun = str(Path(sys.executable).parent / "rerun")
    verify = subprocess.run([rerun, "rrd", "verify", str(rrd)], capture_output=True, text=True)
    assert verify.returncode == 0, verify.stdout + verify.stderr
    printed = subprocess.run([rerun, "rrd", "print", str(rrd)], capture_output=True, text=True)
    for path in (
        f"/plots/{A}/planner/expanded",
        f"/plots/{A}/planner/replans",
        f"/plots/{A}/forecasts/holds",
        f"/world/plans/{A}/committed",
        f"/world/plans/{A}/rest",
        f"/agents/{A}/log",
    ):
        assert f" - {path} - " in printed.stdout, path
