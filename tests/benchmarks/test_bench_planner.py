"""The planner benchmark's own logic: reading both planners' outputs, scoring, judging."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _load() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_planner", ROOT / "benchmarks/planner.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


bench = _load()
PAPER = bench.Problem(
    "recycling",
    "recycling",
    "paper-7x7",
    bench.RECYCLING_DOMAIN,
    bench.RECYCLING_PROBLEMS / "paper-7x7.pddl",
)

KAIROS_LOG = """\
[   0.004s] [orchestrator] engine M2: 121 durative actions compressed
[   0.010s] [search] plan 0 with 38 actions, cost 47.02699999999999
[   0.010s] [search] plan of cost 50 with 38 actions (57 expanded, 58 evaluated)
[   0.023s] [search] plan 1 with 30 actions, cost 36.02
[   0.135s] [search] plan of cost 34.02000000000002 with 56 actions (699 expanded)
[  12.032s] [search] plan 2 with 28 actions, cost 34.018000000000015
kairos: solved (exhausted), cost 34.018
"""


def _result(problem: str, planner: str, makespan: float | None, valid: bool = True) -> Any:
    p = bench.Problem("ipc", "d", problem, Path("d.pddl"), Path(f"{problem}.pddl"))
    found = () if makespan is None else (bench.Found(1.0, makespan * 2), bench.Found(2.0, makespan))
    plan_file = None if makespan is None else Path("plan")
    outcome = bench.Outcome("solved", 0, 3.0, found, plan_file)
    return bench.Result(p, planner, outcome, valid, makespan if valid else None, None)


def test_kairos_plan_times_are_its_anytime_plans_only() -> None:
    assert bench.kairos_times(KAIROS_LOG) == [0.010, 0.023, 12.032]


def test_cbdi_plan_times_count_parse_and_ground() -> None:
    report = {
        "seconds": {"parse": 0.01, "ground": 0.02, "search": 3.0},
        "improvements": [
            {"seconds": 0.1, "makespan": 47.0, "actions": 38},
            {"seconds": 2.0, "makespan": 34.0, "actions": 28},
        ],
    }
    found = bench.cbdi_found(report)
    assert [round(f.seconds, 3) for f in found] == [0.13, 2.03]
    assert [f.makespan for f in found] == [47.0, 34.0]
    assert bench.cbdi_found({"status": "timeout"}) == ()


def test_validated_makespan_is_read_only_from_a_valid_verdict() -> None:
    assert bench.validated_makespan("plan valid, makespan 34.027\n") == 34.027
    assert bench.validated_makespan("error: ... plan invalid") is None


def test_quality_is_the_best_makespan_over_ones_own_and_zero_when_unsolved() -> None:
    results = [
        _result("p1", "cbdi", 10.0),
        _result("p1", "kairos", 8.0),
        _result("p2", "cbdi", None),
        _result("p2", "kairos", 5.0),
        _result("p3", "cbdi", 4.0, valid=False),  # an invalid plan scores nothing
        _result("p3", "kairos", 6.0),
    ]
    q = bench.qualities(results)
    assert q[("ipc/d/p1", "cbdi")] == pytest.approx(0.8)
    assert q[("ipc/d/p1", "kairos")] == 1.0
    assert q[("ipc/d/p2", "cbdi")] == 0.0
    assert q[("ipc/d/p3", "cbdi")] == 0.0 and q[("ipc/d/p3", "kairos")] == 1.0


def test_time_ratio_covers_only_problems_both_solve() -> None:
    results = [
        _result("p1", "cbdi", 10.0),
        _result("p1", "kairos", 8.0),
        _result("p2", "cbdi", None),
        _result("p2", "kairos", 5.0),
    ]
    assert bench.time_ratios(results, "cbdi", "kairos") == [1.0]
    assert bench.geometric_mean([2.0, 8.0]) == pytest.approx(4.0)
    assert bench.geometric_mean([]) is None


def test_the_optimum_is_reached_by_the_first_plan_within_epsilons_of_it() -> None:
    found = [bench.Found(0.1, 47.037), bench.Found(0.7, 36.029), bench.Found(2.1, 34.027)]
    assert bench.reached(found, 34.0) == found[2]
    assert bench.reached(found[:2], 34.0) is None


def test_a_row_flags_an_invalid_plan_and_scores_it_zero() -> None:
    r = bench.row(_result("p3", "cbdi", 4.0, valid=False), 0.0)
    assert (r["solved"], r["valid"], r["quality"]) == ("no", "NO", "0.000")
    assert r["best_makespan"] == "4.000"  # what the planner claimed
    assert list(r) == list(bench.COLUMNS)
    assert bench.row(_result("p2", "cbdi", None), 0.0)["valid"] == ""


def test_table_aligns_columns() -> None:
    rows = [bench.row(_result(p, "cbdi", 1.0), 1.0) for p in ("p1", "long-problem-name")]
    lines = bench.table(rows).splitlines()
    assert len(lines) == 3 and lines[0].startswith("problem")
    assert lines[1].index("cbdi") == lines[2].index("cbdi")


def test_problems_lists_the_suite_then_recycling_maps_by_size(tmp_path: Path) -> None:
    (tmp_path / "dom").mkdir()
    for name in ("domain", "p02", "p01"):
        (tmp_path / "dom" / f"{name}.pddl").write_text("")
    (tmp_path / "notes").mkdir()  # a folder with no domain is skipped
    keys = [p.key for p in bench.problems(tmp_path)]
    assert keys[:2] == ["ipc/dom/p01", "ipc/dom/p02"]
    assert keys[2:] == [
        "recycling/recycling/paper-7x7",
        "recycling/recycling/warehouse-15x15",
        "recycling/recycling/campus-30x30",
    ]
    assert [p.suite for p in bench.problems(None)] == ["recycling"] * 3


def test_execute_kills_a_process_at_its_limit() -> None:
    code, _, _, wall = bench.execute([sys.executable, "-c", "import time; time.sleep(30)"], 0.5)
    assert code == -9 and wall < 10


def test_judge_flags_a_plan_the_validator_rejects(tmp_path: Path) -> None:
    plan = tmp_path / "bad.plan"
    plan.write_text("0.000: (move robot1 c_0_1 c_5_5) [1.000]\n")
    outcome = bench.Outcome("solved", 0, 1.0, (bench.Found(0.1, 1.0),), plan)
    result = bench.judge(PAPER, "cbdi", outcome)
    assert not result.solved and result.note.startswith("INVALID")
    assert result.moves == 1


def test_judge_accepts_kairos_own_plan_with_the_validators_makespan(tmp_path: Path) -> None:
    outcome = bench.run_kairos(PAPER, 2.0, tmp_path / "paper.plan")
    result = bench.judge(PAPER, "kairos", outcome)
    assert result.solved and result.makespan is not None
    assert result.makespan == pytest.approx(outcome.found[-1].makespan, abs=1e-3)
    assert result.moves is not None and result.moves >= 22


def test_reuse_reads_back_the_other_planners_runs_for_scoring(tmp_path: Path) -> None:
    solved, unsolved = _result("p1", "kairos", 10.0), _result("p2", "kairos", None)
    mine = _result("p1", "cbdi", 20.0)
    path = tmp_path / "old.csv"
    bench.write_csv([solved, unsolved, mine], path)
    todo = [solved.problem, unsolved.problem]
    back = bench.reuse(path, todo, ["cbdi"])
    assert [(r.problem.key, r.planner, r.solved) for r in back] == [
        ("ipc/d/p1", "kairos", True),
        ("ipc/d/p2", "kairos", False),
    ]
    assert back[0].makespan == 10.0 and back[0].outcome.found[0] == bench.Found(1.0, 20.0)
    assert bench.qualities([mine, *back])[("ipc/d/p1", "cbdi")] == 0.5
    assert bench.reuse(path, todo[1:], ["cbdi"])[0].problem.key == "ipc/d/p2"  # only todo


def test_reuse_skips_only_the_runs_redone_now(tmp_path: Path) -> None:
    runs = [_result(p, pl, 10.0) for p in ("p1", "p2") for pl in ("cbdi", "kairos")]
    path = tmp_path / "old.csv"
    bench.write_csv(runs, path)
    back = bench.reuse(path, [r.problem for r in runs], {("ipc/d/p1", "cbdi")})
    assert [(r.problem.name, r.planner) for r in back] == [
        ("p1", "kairos"),
        ("p2", "cbdi"),
        ("p2", "kairos"),
    ]


@pytest.mark.parametrize("content", [None, "not,a,table\n1,2,3\n"])
def test_a_bad_reuse_file_is_reported_before_any_run(tmp_path: Path, content: str | None) -> None:
    path = tmp_path / "old.csv"
    if content is not None:
        path.write_text(content)
    argv = [
        "--planners",
        "cbdi",
        "--only",
        "^$",
        "--reuse",
        str(path),
        "--csv",
        str(tmp_path / "o"),
    ]
    assert bench.main(argv) == 2
    assert not (tmp_path / "o").exists()
