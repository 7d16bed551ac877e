"""The fleet benchmark without long runs: its lower bound on hand-made maps, the claim
changes read back from a real recording, the table and figure from a CSV, and one real
two-robot lockstep run of the smallest map through the whole harness."""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path
from types import ModuleType

import pytest
from cbdi_recycling.maps import parse_map

from cbdi import keys
from cbdi.wire.agent import Claim
from cbdi.wire.base import encode
from cbdi.wire.world import Tick
from cbdi_monitor.recorder import McapRecorder
from pngcheck import read_png

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))


def _module(name: str) -> ModuleType:
    return importlib.import_module(name)


fleet = _module("fleet")
bound = _module("fleet_bound")

# A corridor: two robots at the left, a bin at the right end, two items on the way.
CORRIDOR = '''
name = "line"
grid = """
AA.L..L.B
"""
'''


def test_the_bound_on_a_corridor_is_what_the_derivation_gives() -> None:
    m = parse_map(CORRIDOR)
    # Items at x=3 and x=6; starts x=0,1; the bin at x=8, its side x=7.
    # trip (1 robot, start x=0): item x=6: 6 moves + 3 + 1 move + 3 = 13.
    one = bound.fleet_bound(m, 1)
    assert one.trip == 13.0
    # work: arrivals: x=3 from x=0 (3, nearest of start/other item/bin side),
    # x=6 from x=7 (1); one run of recycles (capacity 3) from the nearest item: 1.
    # moves 3 + 1 + 1 = 5, plus 2 items x (3 + 3) = 17.
    assert one.work == 17.0 and one.value == 17.0 and one.term == "work"
    two = bound.fleet_bound(m, 2)
    assert two.trip == 12.0  # the second start is a cell nearer
    assert two.work == (2 + 1 + 1 + 12) / 2  # x=3 now 2 moves from the start at x=1
    with pytest.raises(ValueError, match="2 start cells"):
        bound.fleet_bound(m, 3)


def test_the_bound_never_exceeds_the_paper_maps_optimum() -> None:
    """paper-7x7, one robot: the static optimum is 22 moves and 3 pickups and recycles
    (Table I), 40 s; a lower bound must stay below it."""
    m = bound.scenario_map(ROOT / "domains/recycling/scenarios/paper-7x7.toml")
    b = bound.fleet_bound(m, 1)
    assert 0 < b.value <= 22 + 3 * 6


def _claim(agent: str, item: str, epoch: int, cost: float, released: bool = False) -> Claim:
    return Claim(agent=agent, group="team", item=item, epoch=epoch, cost=cost, released=released)


def test_claim_changes_count_owners_that_change_from_epoch_to_epoch(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    recorder = McapRecorder(path)
    epochs = [
        # robot1 then robot2 (cheaper, within the window) claim p1 in one epoch: robot2
        # owns it at the tick; robot1 owning it in between is no change.
        [_claim("robot1", "p1", 0, 5.0), _claim("robot2", "p1", 0, 2.0)],
        [_claim("robot1", "p2", 1, 1.0)],  # p2: robot1
        [_claim("robot2", "p1", 0, 0.0, released=True)],  # p1 back to robot1: 1
        # robot1 gives p1 up and robot2 claims it again: robot2 (2)
        [_claim("robot1", "p1", 0, 0.0, released=True), _claim("robot2", "p1", 9, 3.0)],
    ]
    log = 1000
    for epoch, claims in enumerate(epochs):
        recorder.write(
            keys.CLOCK,
            encode(
                Tick(epoch=epoch, time=float(epoch), epoch_duration=1.0, speed=0.0, lockstep=True)
            ),
            log_ns=log,
        )
        for c in claims:
            log += 1
            recorder.write(f"cbdi/{c.agent}/scheduler/claims", encode(c), log_ns=log)
            recorder.write("cbdi/robot1/scheduler/other", encode(c), log_ns=log)  # ignored
    recorder.finish_file()
    assert fleet.claim_changes(path) == 2


def test_a_summary_gives_the_figures() -> None:
    summary = {
        "result": "done",
        "sim_time": 100.0,
        "trace_digest": "abc",
        "stats": {
            "litter_recycled": 4,
            "litter_held": 0,
            "litter_on_ground": 0,
            "agents": {
                "robot10": {"moves": 10, "busy": 50.0},
                "robot2": {"moves": 30, "busy": 100.0},
            },
        },
        "actions": {"robot2": {"actions": 40}, "robot10": {"actions": 20}},
        "planner": {"total": {"plans": 15}},
    }
    run = fleet.from_summary("m", 2, 1, 0, summary, 3, 9.5)
    assert run.mission_time == 100.0 and run.items == 4 and run.moves == 40
    assert run.busy_fractions == [1.0, 0.5]  # robot2 before robot10
    assert run.searches == 15 and run.actions == 60 and run.claim_changes == 3
    late = fleet.from_summary("m", 2, 1, 0, {**summary, "result": "time_limit"}, 0, 1.0)
    assert late.mission_time is None and late.restarts == 0
    killed = {**summary, "restarts": {"world": 1, "robot2/planner": 2, "router": 0}}
    assert fleet.from_summary("m", 2, 1, 0, killed, 0, 1.0).restarts == 3
    stalled = {**summary, "stalls": {"robot2/executor": 2}, "freezes": {"robot2/planner": 1}}
    run = fleet.from_summary("m", 2, 1, 0, stalled, 0, 1.0)
    assert (run.stalls, run.freezes, run.restarts) == (2, 1, 0)


WAREHOUSE = "warehouse-15x15-bdi"


def test_the_table_and_figure_from_a_csv(tmp_path: Path) -> None:
    runs = []
    for n, t in ((1, 240.0), (1, 260.0), (2, 120.0), (2, 130.0)):
        busy = json.dumps([0.9] * n)
        figures = (9, 9, 180 // n, 90, 18, n - 1, busy, 10.0, "d", "")
        runs.append(fleet.FleetRun(WAREHOUSE, n, len(runs) + 1, "done", 0, t, *figures))
    late = (9, 7, 50, 60, 9, 0, "[0.5, 0.4]", 30.0, "d", "time", 2)
    runs.append(fleet.FleetRun(WAREHOUSE, 2, 9, "time_limit", 0, None, *late))
    stalled = (9, 9, 60, 70, 9, 0, "[0.8, 0.7]", 30.0, "e", "", 0, 3, 1)
    runs.append(fleet.FleetRun(WAREHOUSE, 2, 10, "done", 0, 125.0, *stalled))
    fleet.write_csv(runs, tmp_path / "fleet.csv")
    assert fleet.read_csv(tmp_path / "fleet.csv") == runs
    out = tmp_path / "out"
    code = fleet.main(
        ["--maps", "warehouse-15x15-bdi", "--agents", "1", "2", "16", "--reuse",
         str(tmp_path / "fleet.csv"), "--out", str(out)]
    )  # fmt: skip
    assert code == 0
    text = (out / "fleet.md").read_text()
    assert "| 1 | 2/2 | 250.0 ± 14.1" in text and "117.0 (work)" in text
    assert "| 2 | 3/4 | 125.0" in text and "| 2.00 |" in text  # speed-up 250/125
    assert "| 16 | the map has fewer start cells" in text
    assert "N=2 seed 9: time_limit" in text and "Work shared" in text
    assert "1 of 6 runs had services restarted" in text and "x2 seed 9" in text
    assert "1 of 6 runs had lockstep members that missed" in text and "x2 seed 10" in text
    width, height = read_png(out / "fleet.png")[:2]
    assert width > 400 and height > 200


@pytest.mark.timeout(300)
def test_two_robots_on_the_small_map_through_the_harness(tmp_path: Path) -> None:
    """A real lockstep run: the two robots share the three items by claims."""
    code = fleet.main(
        ["--maps", "paper-7x7-k2-bdi", "--agents", "2", "--seeds", "1", "--out", str(tmp_path)]
    )
    assert code == 0
    (run,) = fleet.read_csv(tmp_path / "fleet.csv")
    assert run.result == "done" and run.mission_time is not None and run.recycled == run.items
    assert (
        run.mission_time
        >= bound.fleet_bound(
            bound.scenario_map(ROOT / "domains/recycling/scenarios/paper-7x7-k2-bdi.toml"), 2
        ).value
    )
    assert run.actions > 0 and run.searches > 0 and len(run.busy_fractions) == 2
