"""The planner's command line: plan, validate, exit codes, JSON statistics."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from cbdi_planner.cli import main

ROOT = Path(__file__).resolve().parents[2]
DOMAIN = ROOT / "domains/recycling/pddl/domain.pddl"
PAPER = ROOT / "domains/recycling/problems/paper-7x7.pddl"
KAIROS = Path(sys.executable).parent / "kairos"

SMALL = """(define (problem small) (:domain recycling)
  (:objects robot1 - robot c_0_0 c_1_0 c_2_0 - cell bin1 - bin p1 - plastic)
  (:init (map_loaded) (in robot1 c_1_0) (free c_2_0) (bin_pose bin1 c_0_0)
         (near c_0_0 c_1_0) (near c_1_0 c_0_0) (near c_1_0 c_2_0) (near c_2_0 c_1_0)
         (litter_pose p1 c_2_0) (= (loaded_amount robot1) 0) (= (detection_depth robot1) 1))
  (:goal (and (recycled p1))))
"""


def test_plan_prints_a_plan_kairos_accepts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "plan.txt"
    assert main(["plan", str(DOMAIN), str(PAPER), "-o", str(out)]) == 0
    printed = capsys.readouterr()
    assert printed.out == out.read_text()
    assert "facts=" in printed.err and "expanded=" in printed.err
    done = subprocess.run(
        [str(KAIROS), "validate", str(DOMAIN), str(PAPER), str(out)], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert main(["validate", str(DOMAIN), str(PAPER), str(out)]) == 0


def test_json_report_has_statistics_and_the_plan(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plan", str(DOMAIN), str(PAPER), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["status"] == "solved"
    assert report["grounded"]["facts"] > 0 and report["grounded"]["actions"] > 0
    assert report["search"]["expanded"] > 0
    assert set(report["seconds"]) == {"parse", "ground", "search"}
    moves = [s for s in report["plan"] if s["action"].startswith("move")]
    assert len(moves) >= 22  # the paper: 22 moves suffice
    assert report["makespan"] == pytest.approx(
        max(s["time"] + s["duration"] for s in report["plan"])
    )


def test_exit_codes_tell_bad_input_unsolvable_timeout_and_invalid(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    broken = tmp_path / "broken.pddl"
    broken.write_text("(define (problem x) (:domain recycling)\n  (:objects robot1 - robot\n")
    assert main(["plan", str(DOMAIN), str(broken)]) == 2
    assert f"{broken}:" in capsys.readouterr().err
    assert main(["plan", str(DOMAIN), str(tmp_path / "missing.pddl")]) == 2
    walled = tmp_path / "walled.pddl"
    walled.write_text(SMALL.replace("(near c_1_0 c_2_0) (near c_2_0 c_1_0)", ""))
    assert main(["plan", str(DOMAIN), str(walled)]) == 3
    assert main(["plan", str(DOMAIN), str(PAPER), "--expansions", "3", "--search", "bfs"]) == 4
    small = tmp_path / "small.pddl"
    small.write_text(SMALL)
    bad = tmp_path / "bad.plan"
    bad.write_text(
        "0.000: (move robot1 c_1_0 c_2_0) [1.000]\n0.500: (pickup robot1 p1 c_2_0) [3.000]\n"
    )  # moves in, picks up too soon
    capsys.readouterr()
    assert main(["validate", str(DOMAIN), str(small), str(bad)]) == 5
    assert "pickup" in capsys.readouterr().err


def test_cbdi_plan_is_the_same_command() -> None:
    done = subprocess.run(
        [str(Path(sys.executable).parent / "cbdi"), "plan", str(DOMAIN), str(PAPER)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("0.000: (")
