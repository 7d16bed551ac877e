"""Table I's harness without `cbdi up`: statistics, CSV round trip, report, figure, CLI.

A fake runner stands in for the processes (its moves are a function of the task), so
these tests take a second; the harness's own processes are exercised only where they
are cheap (a killed process group, a port lease, the clairvoyant problem's text).
"""

from __future__ import annotations

import importlib
import io
import random
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from cbdi.agentfile import PlanningSettings
from pngcheck import read_png

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the harness's modules import each other


def _module(name: str) -> ModuleType:
    return importlib.import_module(name)


table1 = _module("table1")
model = _module("table1_model")
stats = _module("table1_stats")
summary = _module("table1_summary")
report = _module("table1_report")
runner = _module("table1_runner")
bounds = _module("table1_bounds")

S412 = model.Situation(4, 1, 2)
S813 = model.Situation(8, 1, 3)

SUMMARY = {
    "scenario": "paper-7x7",
    "result": "done",
    "reason": "",
    "sim_time": 107.0,
    "trace_digest": "9f2c",
    "stalls": {"robot1/planner": 2, "robot1/executor": 1},
    "stats": {"agents": {"robot1": {"moves": 48, "pickups": 3, "recycled": 3, "busy": 85.6}}},
    "planner": {
        "agents": {
            "robot1": {
                "plans": 8,
                "replans": 6,
                "forecast_repairs": 2,
                "improvements": 1,
                "replans_by": {"new": 4, "repair": 2, "revise": 0, "improve": 0},
            }
        }
    },
}


def fake_run(task: Any) -> Any:
    """Moves and time as a function of the task; seed 3 online fails without a summary."""
    if task.mode == "online" and task.seed == 3:
        return model.Run(task, "no_summary", reason="exit 1: router exited", exit=1, speed=0.0)
    online = task.mode == "online"
    moves = 50 - (8 if online else 0) + task.seed % 3 + task.situation.det_area
    return model.Run(
        task,
        "done",
        moves=moves,
        sim_time=80.0 + (12.5 if online else 0.0) + task.seed,
        busy=72.0 if online else 76.0,
        recycled=3,
        plans=4,
        replans=3,
        replans_new=2,
        replans_repair=1,
        replans_revise=0,
        replans_improve=0,
        forecast_repairs=1 if online else 0,
        improvements=0,
        planning_speed=None if task.factor == 1 else 100.0 * task.factor,
        speed=1.0 if task.clock == "realtime" else 0.0,
        stalls=2 if (task.mode, task.seed) == ("offline", 2) else 0,
        wall=12.345,
    )


def fake_bounds(tasks: list[Any]) -> list[Any]:
    cases = sorted({(t.situation.move_step, t.seed) for t in tasks})
    out = [bounds.Bound("static", None, None, 22, 34.027, "solved", timeout=10.0)]
    return out + [
        bounds.Bound("clairvoyant", m, s, 22 + s % 2, 34.0, "solved", 80, 30.0) for m, s in cases
    ]


def _tasks(seeds: int = 5) -> list[Any]:
    return table1.tasks_of((S412, S813), seeds, (1.0,), realtime=False)


# ---------------------------------------------------------------- statistics


def test_the_bootstrap_interval_is_deterministic_order_free_and_holds_the_mean() -> None:
    values = [40.0, 44.0, 46.0, 52.0, 48.0, 41.0, 39.0]
    first = stats.bootstrap_interval(values)
    shuffled = values[:]
    random.Random(3).shuffle(shuffled)
    assert stats.bootstrap_interval(shuffled) == first
    assert stats.bootstrap_interval(values) == first
    mean = sum(values) / len(values)
    assert first.low < mean < first.high
    assert min(values) <= first.low and first.high <= max(values)
    assert stats.bootstrap_interval([]) is None
    assert stats.bootstrap_interval([7.0]) == stats.Interval(7.0, 7.0)


def test_describe_gives_the_sample_deviation() -> None:
    sample = stats.describe([2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0])
    assert (sample.n, sample.mean) == (8, 5.0)
    assert sample.sd == pytest.approx(2.138, abs=1e-3)  # n-1 in the denominator
    assert stats.describe([]) == stats.Sample(0, None, None, None)
    assert stats.describe([3.0]).sd == 0.0


def test_paired_differences_pair_by_seed_and_skip_unpaired_seeds() -> None:
    online = {2: 46.0, 1: 40.0, 4: 50.0}
    offline = {1: 44.0, 3: 60.0, 2: 54.0}
    assert stats.paired_differences(online, offline) == [(1, -4.0), (2, -8.0)]


def test_a_verdict_needs_an_interval_clear_of_zero_and_enough_pairs() -> None:
    def verdict(values: list[float]) -> str:
        return stats.verdict(stats.describe(values), lower_is_better="on", higher_is_better="off")

    assert verdict([-4.0, -6.0, -5.0]) == "on"
    assert verdict([4.0, 6.0, 5.0]) == "off"
    assert verdict([-4.0, 6.0, 1.0]) == "no clear difference"
    assert verdict([-4.0, -6.0]).startswith("too few pairs")


# ---------------------------------------------------------------- rows and failures


def test_failed_runs_are_counted_named_and_left_out_of_means_and_pairs() -> None:
    runs = [fake_run(t) for t in _tasks(seeds=5)]
    rows = summary.rows_of(runs, fake_bounds(_tasks(seeds=5)))
    row = next(r for r in rows if r.situation == S412)
    assert (row.offline.runs, row.offline.failed) == (5, 0)
    assert (row.online.runs, row.online.failed) == (5, 1)
    assert row.online.failures == ("seed 3: no_summary",)
    assert row.online.moves.n == 4 and row.moves_diff.n == 4  # seed 3 unpaired
    assert row.moves_diff.mean == -8.0 and row.moves_verdict == summary.ONLINE_BETTER
    assert row.time_verdict == summary.OFFLINE_FASTER
    assert row.clairvoyant.n == 5 and row.clairvoyant.mean == pytest.approx(22.6)


def test_the_markdown_shows_failures_verdicts_paper_and_bounds() -> None:
    runs = [fake_run(t) for t in _tasks(seeds=5)]
    text = report.render_markdown(runs, fake_bounds(_tasks(seeds=5)))
    assert "| 4,1,2 | 5/5 | 0/1 | 0/0 |" in text  # the fake runs report no trace
    assert "- x1 4,1,2 online seed 3: no_summary" in text
    assert "56.0 ± 2.3" in text and "13.5" in text  # the paper's mu, sigma and mu+
    assert "22 moves, makespan 34.0" in text
    assert "online is better on moves in 2 of 2 situations" in text
    assert "on mission time in 0 of 2 (offline faster: 2)" in text
    assert "wall" not in text and "12.345" not in text
    assert "20 lockstep runs (speed 0 (flat out)): seeds 1..5" in text
    assert "- 4,1,2 offline seed 2: 2 stalled epochs" in text
    # Idle: 1 - busy / time, per mode over the runs that recycled all, and paired.
    idle = next(line for line in text.splitlines() if "idle (% of the mission" in line)
    assert "offline 8.4 ±" in idle and "online 24.6 ±" in idle and "+16.2" in idle


def test_the_real_time_table_stands_beside_the_lockstep_runs() -> None:
    tasks = table1.tasks_of((S412,), 2, (1.0,), realtime=True)
    assert [t.clock for t in tasks].count("realtime") == 2
    text = report.render_markdown([fake_run(t) for t in tasks], [])
    line = next(x for x in text.splitlines() if x.startswith("| 4,1,2 | 1 |"))
    assert line.endswith("| 52, 81.0 (done) | 52 | 44, 93.5 (done) | 44 |")
    # Several real-time seeds per situation, and how many situations online wins.
    tasks = table1.tasks_of((S412, S813), 1, (1.0,), realtime=True, realtime_seeds=3)
    real = [t for t in tasks if t.clock == "realtime"]
    assert sorted({t.seed for t in real}) == [1, 2, 3] and len(real) == 12
    text = report.render_markdown([fake_run(t) for t in tasks], [])
    assert "Online fewer moves than offline in real time (the mean of its runs): " in text
    for seed in (2, 3):
        assert any(x.startswith(f"| 8,1,3 | {seed} | ") for x in text.splitlines()), text


# ---------------------------------------------------------------- CSV and outputs


def test_the_csv_round_trip_keeps_every_run(tmp_path: Path) -> None:
    runs = [fake_run(t) for t in _tasks(seeds=3)]
    random.Random(1).shuffle(runs)
    written = model.write_csv(runs, tmp_path / "t.csv")
    assert model.read_csv(tmp_path / "t.csv") == written
    assert [r.task.sort_key() for r in written] == sorted(r.task.sort_key() for r in runs)


def test_reuse_renders_the_same_markdown_and_a_real_png(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    csv = tmp_path / "run" / "table1.csv"
    argv = ["--seeds", "4", "--only", "4,1,2;8,1,3", "--planning-speeds", "1,0.25"]
    argv += ["--jobs", "2", "--csv", str(csv)]
    assert table1.main(argv, runner=fake_run, bound_maker=fake_bounds) == 0
    first = (tmp_path / "run" / "table1.md").read_text()
    assert capsys.readouterr().out == first
    again = tmp_path / "again" / "table1.csv"
    assert table1.main(["--reuse", str(csv), "--csv", str(again)]) == 0
    assert (tmp_path / "again" / "table1.md").read_text() == first
    assert "planning speed x0.25 (25 expansions per simulated s)" in first
    assert not again.exists()  # --reuse reads the CSV, it writes none
    width, height, rows = read_png(tmp_path / "again" / "table1.png")
    assert width > 500 and height > 300
    assert len({bytes(r) for r in rows}) > 10  # something is drawn


@pytest.mark.parametrize("content", [None, "not,a,table\n1,2,3\n"])
def test_a_bad_reuse_file_exits_2(tmp_path: Path, content: str | None) -> None:
    path = tmp_path / "old.csv"
    if content is not None:
        path.write_text(content)
    assert table1.main(["--reuse", str(path), "--csv", str(tmp_path / "o.csv")]) == 2
    assert not (tmp_path / "o.md").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--seeds", "0"], "must be at least 1"),
        (["--jobs", "0"], "must be at least 1"),
        (["--jobs", "two"], "expected an integer"),
        (["--only", "4,1"], "not move,det,known"),
        (["--only", "4,x,2"], "not move,det,known"),
        (["--only", "5,1,2"], "not a situation of Table I"),
        (["--only", " "], "no situation given"),
        (["--planning-speeds", "0"], "must be > 0"),
        (["--up-arg", "'--unclosed"], "cannot split"),
    ],
)
def test_the_cli_refuses_bad_arguments(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as stop:
        table1.main(argv, runner=fake_run, bound_maker=fake_bounds)
    assert stop.value.code == 2
    assert message in capsys.readouterr().err


def test_only_keeps_the_papers_row_order_and_drops_repeats() -> None:
    chosen = model.parse_situations("8,1,3 4,1,2;4,1,2")
    assert chosen == (S412, S813)


def test_a_summary_gives_the_robots_and_its_planners_counts() -> None:
    task = model.Task(S412, "online", 1)
    run = model.run_from_summary(model.Run(task, "no_summary", speed=0.0), SUMMARY)
    assert (run.result, run.moves, run.sim_time, run.recycled) == ("done", 48, 107.0, 3)
    assert (run.replans_new, run.replans_repair, run.forecast_repairs) == (4, 2, 2)
    assert (run.trace_digest, run.stalls) == ("9f2c", 3)
    assert run.busy == 85.6 and run.idle is not None and abs(run.idle - 20.0) < 1e-9
    assert run.ok
    assert run.speed == 0.0  # what was passed is kept
    empty = model.run_from_summary(model.Run(task, "no_summary", exit=1), {"result": "failed"})
    assert empty.moves is None and not empty.ok


# ---------------------------------------------------------------- running cbdi up


def test_planning_speeds_other_than_1_need_the_flag_and_a_default() -> None:
    assert runner.check_planning_speeds((1.0,), None, False) == ""
    assert "no --planning-speed" in runner.check_planning_speeds((0.25, 1.0), 400.0, False)
    assert "planning_speed" in runner.check_planning_speeds((4.0,), None, True)
    assert runner.check_planning_speeds((0.25, 4.0), 400.0, True) == ""


def test_the_command_scales_the_planning_speed_and_ends_with_the_clock() -> None:
    options = runner.UpOptions(
        up_args=("--speed", "40"),
        default_speed=400.0,
        pass_speed=True,
        run_timeout=60.0,
        lockstep_speed=0.0,
    )
    argv = runner.up_argv(model.Task(S813, "offline", 7, 0.25, "realtime"), options, 4242)
    text = " ".join(argv[1:])
    assert "up paper-7x7 --json --quiet --mode offline --seed 7 --option move_step=8" in text
    assert "--option det_area=1 --option known_litter=3 --port 4242 --timeout 60" in text
    assert "--planning-speed 100 --speed 40 --speed 1 --no-lockstep" in text
    plain = runner.up_argv(model.Task(S813, "online", 1), runner.UpOptions(), 1)
    assert "--planning-speed" not in plain and "--no-lockstep" not in plain
    assert "--speed" not in plain  # the scenario's pace unless one is given
    flat = runner.up_argv(model.Task(S813, "online", 1), options, 1)
    assert " ".join(flat).endswith("--planning-speed 400 --speed 0 --speed 40")


def test_the_agent_files_planning_speed_is_read_when_present(tmp_path: Path) -> None:
    agent = tmp_path / "a.toml"
    agent.write_text("[planning]\nmode = 'online'\nplanning_speed = 500\n")
    assert runner.agent_planning_speed(agent) == 500.0
    agent.write_text("[planning]\nmode = 'online'\n")  # the reader's default applies
    assert runner.agent_planning_speed(agent) == PlanningSettings().planning_speed
    assert runner.agent_planning_speed(None) is None


def test_ports_held_by_runs_are_never_handed_out_twice() -> None:
    pool = runner.PortPool()
    with pool.lease() as a, pool.lease() as b, pool.lease() as c:
        assert len({a, b, c}) == 3


def test_a_run_whose_router_lost_its_port_runs_again_on_another(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import json

    ports: list[int] = []
    taken = {**SUMMARY, "result": "failed", "reason": "our router could not listen on tcp/x"}

    def execute(argv: list[str], timeout: float) -> tuple[int, str, str, float]:
        ports.append(int(argv[argv.index("--port") + 1]))
        return (
            (1 if len(ports) == 1 else 0),
            json.dumps(taken if len(ports) == 1 else SUMMARY),
            "",
            1.0,
        )

    monkeypatch.setattr(runner, "execute", execute)
    run = runner.run_task(model.Task(S412, "online", 1), runner.UpOptions(), runner.PortPool())
    assert run.result == "done" and len(ports) == 2
    always = lambda argv, timeout: (1, json.dumps(taken), "", 1.0)  # noqa: E731
    monkeypatch.setattr(runner, "execute", always)
    run = runner.run_task(model.Task(S412, "online", 1), runner.UpOptions(), runner.PortPool())
    assert run.result == "failed" and "could not listen" in run.reason  # tried, then said


def test_execute_kills_the_whole_process_group_at_its_limit(tmp_path: Path) -> None:
    pid_file = tmp_path / "child.pid"
    script = f"sleep 60 & echo $! > {pid_file}; wait"
    code, _, _, wall = runner.execute(["sh", "-c", script], 0.5)
    assert code == -9 and wall < 20
    child = int(pid_file.read_text())
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        state = subprocess.run(["ps", "-o", "stat=", "-p", str(child)], capture_output=True)
        if not state.stdout.strip() or state.stdout.strip().startswith(b"Z"):
            break
        time.sleep(0.1)
    else:
        pytest.fail("the child outlived its group's kill")


def test_progress_prints_counts_and_eta_on_a_plain_stream() -> None:
    now = iter([0.0, 10.0, 20.0])
    out = io.StringIO()
    bar = runner.Progress(4, "lockstep", out, clock=lambda: next(now))
    bar.step("one")
    bar.step("two")
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("lockstep [######") and "1/4" in lines[0]
    assert "0:00:10 elapsed, ETA 0:00:30  one" in lines[0]
    assert "2/4 0:00:20 elapsed, ETA 0:00:20  two" in lines[1]


def test_run_all_returns_every_run_sorted_whatever_the_finishing_order() -> None:
    tasks = _tasks(seeds=3)
    runs = runner.run_all(list(reversed(tasks)), fake_run, jobs=3)
    assert [r.task for r in runs] == tasks


# ---------------------------------------------------------------- bounds


def _world(*flags: str) -> Any:
    return bounds.launcher_world(["paper-7x7", "--option", "move_step=4", *flags])


def test_the_clairvoyant_problem_blocks_peoples_cells_while_they_stand_there() -> None:
    world = _world("--seed", "1", "--option", "people_phase=false", "--option", "people_jitter=0")
    timeline = bounds.people_timeline(world, horizon=8)
    assert timeline[:2] == ((0, "person1", (4, 0)), (0, "person2", (6, 3)))
    assert (4, "person1", (3, 0)) in timeline and (8, "person1", (2, 0)) in timeline
    text = bounds.clairvoyant_problem(world.map, timeline)
    init = {line.strip() for line in text.splitlines() if line.strip().startswith("(free")}
    assert "(free c_4_0)" not in init and "(free c_6_3)" not in init  # taken at the start
    assert "(free c_3_0)" in init and "(free c_0_1)" not in init  # the robot's cell
    assert "(at 4 (free c_4_0))" in text and "(at 4 (not (free c_3_0)))" in text
    assert "(at 8 (free c_3_0))" in text
    goal = "(:goal (and (recycled plastic_3_6) (recycled plastic_4_6) (recycled plastic_6_1)))"
    assert goal in text


def test_the_clairvoyant_world_is_the_runs_world_seeded_phase_and_jitter_included() -> None:
    world = _world("--seed", "3", "--option", "people_jitter=2")
    assert world.chance.people_phase and world.chance.people_jitter == 2  # the scenario's phase
    assert world.people[0].move_step == 4 and world.seed == 3
    one = bounds.people_timeline(_world("--seed", "1"), horizon=40)
    again = bounds.people_timeline(_world("--seed", "1"), horizon=40)
    other = bounds.people_timeline(_world("--seed", "2"), horizon=40)
    assert one == again and one != other


def test_bounds_round_trip_through_their_csv(tmp_path: Path) -> None:
    written = fake_bounds(_tasks(seeds=2))
    bounds.write_bounds(list(reversed(written)), tmp_path / "b.csv")
    assert bounds.read_bounds(tmp_path / "b.csv") == written
