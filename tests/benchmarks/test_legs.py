"""benchmarks/legs.py: a run's actions into legs, and where two runs part, from real
MCAP recordings written here."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

from cbdi.wire.agent import ActionStatus
from cbdi.wire.base import encode
from cbdi.wire.world import ActionOutcome, ActionRequest
from cbdi_monitor.recorder import McapRecorder

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
legs = importlib.import_module("legs")

REQUESTS = "cbdi/trace/world/rpc/act/request"
OUTCOMES = "cbdi/world/outcomes/robot1"


def record(path: Path, actions: list[tuple[str, list[str], float, str]]) -> Path:
    """robot1's actions (name, args, end time, status), one after the other, 1 s each."""
    recorder = McapRecorder(path)
    log = 1000
    for n, (action, args, ends, status) in enumerate(actions, 1):
        rid = f"robot1-{n}"
        req = ActionRequest(agent="robot1", action=action, request_id=rid, args=args, duration=1.0)
        out = ActionOutcome(
            agent="robot1",
            request_id=rid,
            action=action,
            status=status,
            reason="" if status == "succeeded" else "blocked",
            epoch=int(ends),
            time=ends,
        )
        recorder.write(REQUESTS, encode(req), log_ns=log)
        recorder.write(OUTCOMES, encode(out), log_ns=log + 1)
        log += 2
    refused = ActionStatus(
        agent="robot1",
        plan_id="p",
        step_id="p-9",
        action="move",
        status="refused",
        reason="at start condition (in robot1 c_7_2) does not hold",
        time=3.0,
    )
    recorder.write("cbdi/robot1/executor/status", encode(refused), log_ns=log)
    recorder.finish_file()
    return path


def move(
    a: str, b: str, ends: float, status: str = "succeeded"
) -> tuple[str, list[str], float, str]:
    return ("move", ["robot1", a, b], ends, status)


def pick(item: str, ends: float) -> tuple[str, list[str], float, str]:
    return ("pickup", ["robot1", item], ends, "succeeded")


def test_one_run_falls_into_legs(tmp_path: Path) -> None:
    path = record(
        tmp_path / "a.mcap",
        [
            move("c1", "c2", 1),
            move("c2", "c3", 2),
            pick("p1", 3),
            move("c3", "c4", 6),
            move("c4", "c5", 7, "failed"),
            pick("p2", 8),
        ],
    )
    run = legs.read_run(str(path), "robot1", frozenset({"move"}))
    assert [(leg.end, leg.moves, leg.ended) for leg in run.legs] == [
        ("pickup robot1 p1", 2, 3.0),
        ("pickup robot1 p2", 1, 8.0),
    ]
    assert run.legs[1].idle == 3.0  # 3 to 8 with 2 s of actions: the failed move is no work
    assert run.moves == 3
    assert any("move failed: blocked" in t for t in run.trouble)
    assert any("refused: at start condition" in t for t in run.trouble)


def test_two_runs_part_where_they_take_up_another_job(tmp_path: Path) -> None:
    a = record(tmp_path / "a.mcap", [move("c1", "c2", 1), pick("p1", 2), pick("p2", 3)])
    b = record(
        tmp_path / "b.mcap",
        [
            move("c1", "c2", 1),
            pick("p1", 2),
            move("c2", "c3", 3),
            pick("p3", 4),
            move("c3", "c2", 5),
            pick("p2", 6),
        ],
    )
    travel = frozenset({"move"})
    lines = list(legs.compare(*(legs.read_run(str(p), "robot1", travel) for p in (a, b))))
    assert lines[-1] == "they part at leg 2: A takes up pickup robot1 p2, B pickup robot1 p3"
    assert "B went the longer way to pickup robot1 p2: 0 moves against 1" in lines


def test_the_command_names_a_recording_without_the_agent(tmp_path: Path) -> None:
    path = record(tmp_path / "a.mcap", [pick("p1", 1)])
    assert legs.main([str(path), "--agent", "robot2"]) == 1
    assert legs.main([str(path)]) == 0
