"""The fleet benchmark: 1 to 16 BDI robots sharing the litter of one map (issue 30).

For each map (`--maps`: recycling BDI scenarios) and fleet size N (`--agents`; a size
beyond the map's start cells is skipped and said so), `--seeds` lockstep runs of
`cbdi up SCENARIO --agents N --seed S --speed 0 --until done --json --record R` with the
seed varying the people (`VARY`: their start on their loop and their pace), `--jobs`
at a time. Per run:

- mission time (simulated s to the last item recycled) and whether it ended `done`;
- moves per item (all robots' moves over the items recycled);
- each robot's busy fraction (simulated seconds in actions over the mission time);
- searches per action: plans the planners published (fresh, repair, revised goal and
  improvement: `cbdi.tally`) over the actions the robots asked the world for;
- claim changes: how often an item's owner (the assignment every scheduler computes
  from the group's claims, `cbdi_scheduler.claims`) became another robot, replayed from
  the run's recording; per item in the table.

Beside each map and N the lower bound of `fleet_bound` (its derivation is in the
markdown). Results: a CSV of runs, a markdown table (means, standard deviations and 95%
bootstrap intervals) and a figure of mission time against N with the bound.

    make bench-fleet  or  .venv/bin/python benchmarks/fleet.py [--maps S ...]
        [--agents 1 2 4 8 16] [--seeds 5] [--jobs 1] [--out benchmarks/results]
        [--reuse CSV]

Virtual time: every figure but wall time is the same on any machine.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from fleet_bound import Bound, fleet_bound, scenario_map
from fleet_report import draw, markdown
from table1_model import summary_of
from table1_runner import GRACE, PortPool, Progress, execute, stop_all

from cbdi import keys
from cbdi.wire.agent import Claim
from cbdi.wire.base import WireError, decode
from cbdi_monitor.reader import read_messages
from cbdi_scheduler.claims import Claims

ROOT = Path(__file__).resolve().parents[1]
CBDI = str(Path(sys.executable).parent / "cbdi")
SCENARIOS = ROOT / "domains/recycling/scenarios"
MAPS = ("warehouse-15x15-bdi", "campus-30x30-bdi")
SIZES = (1, 2, 4, 8, 16)
# What the seed varies by default: where on its loop each person starts, and a step of
# jitter in their pace (the maps' worlds are otherwise the same for every seed).
VARY = ("--option", "people_phase=true", "--option", "people_jitter=1")


@dataclass
class FleetRun:
    """One run's figures (None where the run gave none)."""

    scenario: str
    agents: int
    seed: int
    result: str
    exit: int
    mission_time: float | None
    items: int
    recycled: int
    moves: int
    actions: int
    searches: int
    claim_changes: int
    busy: str  # each robot's busy fraction, JSON list in robot order
    wall: float
    trace_digest: str
    reason: str
    # services restarted (a kill by the freeze watchdog on a machine short of CPU, a
    # crash): such a run is no longer a function of its inputs alone
    restarts: int = 0
    # lockstep members the world stopped waiting for at the ack timeout (a late member's
    # inputs go to a later epoch: the run then depends on the machine's load too)
    stalls: int = 0
    freezes: int = 0  # services the freeze watchdog judged frozen (reported or killed)

    @property
    def busy_fractions(self) -> list[float]:
        return [float(b) for b in json.loads(self.busy or "[]")]


def claim_changes(recording: Path) -> int:
    """How often an item's owner became another robot, over the recorded claims.

    The owners are compared from epoch to epoch (at each clock tick and at the end), not
    after every claim: the claims of one epoch reach the recorder in any order, and what
    the owners were between two of them is no decision any robot acted on.
    """
    observers: dict[str, Claims] = {}
    owners: dict[str, str] = {}
    changes = 0

    def compare() -> None:
        nonlocal changes
        for group, view in sorted(observers.items()):
            for item, owner in sorted(view.assignment().items()):
                before = owners.get(f"{group}/{item}")
                if before is not None and before != owner:
                    changes += 1
                owners[f"{group}/{item}"] = owner

    for m in read_messages(recording):
        if m.key == keys.CLOCK:
            compare()
            continue
        if not m.key.endswith("/scheduler/claims"):
            continue
        try:
            claim = decode(m.payload, Claim, m.key)
        except WireError:
            continue
        view = observers.setdefault(
            claim.group, Claims(agent="#observer", group=claim.group, predicates=frozenset())
        )
        view.on_claim(claim)
    compare()
    return changes


def run_one(
    scenario: str,
    agents: int,
    seed: int,
    ports: PortPool,
    limit: float,
    up_args: Sequence[str] = VARY,
) -> FleetRun:
    """Run one lockstep `cbdi up` and read its summary and recording."""
    with tempfile.TemporaryDirectory(prefix="cbdi-fleet-") as tmp, ports.lease() as port:
        recording = Path(tmp) / "run.mcap"
        argv = [
            CBDI, "up", scenario, "--agents", str(agents), "--seed", str(seed),
            "--speed", "0", "--until", "done", "--json", "--quiet", "--port", str(port),
            "--timeout", str(limit), "--record", str(recording), *up_args,
        ]  # fmt: skip
        code, out, err, wall = execute(argv, limit + GRACE)
        summary = summary_of(out)
        changes = claim_changes(recording) if summary is not None and recording.exists() else 0
    if summary is None:
        tail = " | ".join(err.strip().splitlines()[-3:])
        return FleetRun(
            scenario, agents, seed, "killed" if code == -9 else "no_summary", code,
            None, 0, 0, 0, 0, 0, 0, "[]", round(wall, 3), "", f"exit {code}: {tail}",
        )  # fmt: skip
    return from_summary(scenario, agents, seed, code, summary, changes, wall)


def from_summary(
    scenario: str,
    agents: int,
    seed: int,
    code: int,
    summary: dict[str, Any],
    changes: int,
    wall: float,
) -> FleetRun:
    """The figures of a `cbdi up --json` summary."""
    stats = summary.get("stats", {})
    robots = stats.get("agents", {})
    mission = float(summary.get("sim_time", 0.0))
    names = sorted(robots, key=lambda n: (len(n), n))
    busy = [round(robots[n].get("busy", 0.0) / mission, 4) if mission > 0 else 0.0 for n in names]
    held, ground = stats.get("litter_held", 0), stats.get("litter_on_ground", 0)
    recycled = stats.get("litter_recycled", 0)
    actions = sum(a.get("actions", 0) for a in summary.get("actions", {}).values())
    result = summary.get("result", "")
    return FleetRun(
        scenario=scenario,
        agents=agents,
        seed=seed,
        result=result,
        exit=code,
        mission_time=mission if result == "done" else None,
        items=recycled + held + ground,
        recycled=recycled,
        moves=sum(r.get("moves", 0) for r in robots.values()),
        actions=actions,
        searches=summary.get("planner", {}).get("total", {}).get("plans", 0),
        claim_changes=changes,
        busy=json.dumps(busy),
        wall=round(wall, 3),
        trace_digest=summary.get("trace_digest", ""),
        reason=summary.get("reason", ""),
        restarts=sum(int(n) for n in summary.get("restarts", {}).values()),
        stalls=sum(int(n) for n in summary.get("stalls", {}).values()),
        freezes=sum(int(n) for n in summary.get("freezes", {}).values()),
    )


def write_csv(runs: Sequence[FleetRun], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=[f.name for f in fields(FleetRun)])
        writer.writeheader()
        for run in runs:
            writer.writerow(asdict(run))


def read_csv(path: Path) -> list[FleetRun]:
    out = []
    with path.open() as handle:
        for row in csv.DictReader(handle):
            ints = ("agents", "seed", "exit", "items", "recycled", "moves", "actions")
            ints += ("searches", "claim_changes")
            values: dict[str, Any] = dict(row)
            for name in ints:
                values[name] = int(row[name])
            values["wall"] = float(row["wall"])
            for name in ("restarts", "stalls", "freezes"):  # absent from older files
                values[name] = int(row.get(name) or 0)
            values["mission_time"] = float(row["mission_time"]) if row["mission_time"] else None
            out.append(FleetRun(**values))
    return out


def bounds_of(maps: Sequence[str], sizes: Sequence[int]) -> dict[tuple[str, int], Bound | None]:
    """Each map and size's lower bound (None: the map has fewer start cells)."""
    out: dict[tuple[str, int], Bound | None] = {}
    for name in maps:
        world_map = scenario_map(SCENARIOS / f"{name}.toml")
        for n in sizes:
            out[(name, n)] = fleet_bound(world_map, n) if n <= len(world_map.agent_starts) else None
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--maps", nargs="+", default=list(MAPS), help="recycling BDI scenarios")
    p.add_argument("--agents", nargs="+", type=int, default=list(SIZES), help="fleet sizes")
    p.add_argument("--seeds", type=int, default=5, help="seeds 1..N per map and size")
    p.add_argument("--jobs", type=int, default=1, help="runs at a time")
    p.add_argument("--timeout", type=float, default=1800.0, help="wall seconds per run")
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks/results")
    p.add_argument("--reuse", type=Path, help="render this CSV of runs, run nothing")
    p.add_argument(
        "--planning-speed",
        type=float,
        help="virtual time: expansions per simulated second (default: each scenario's)",
    )
    p.add_argument(
        "--up-arg",
        action="append",
        dest="up_args",
        help="passed to every `cbdi up` instead of the default seeded variation "
        f"({' '.join(VARY)}); repeat it, `--up-arg=--flag` for a flag alone",
    )
    args = p.parse_args(argv)
    for name in args.maps:
        if not (SCENARIOS / f"{name}.toml").is_file():
            p.error(f"--maps: no recycling scenario {name} in {SCENARIOS}")
    if args.seeds < 1 or args.jobs < 1 or any(n < 1 for n in args.agents):
        p.error("--seeds, --jobs and --agents take positive numbers")
    bounds = bounds_of(args.maps, args.agents)
    if args.reuse is not None:
        runs = read_csv(args.reuse)
    else:
        runs = run_all(args, bounds)
        write_csv(runs, args.out / "fleet.csv")
    text = markdown(runs, bounds, args.maps, args.agents)
    (args.out / "fleet.md").parent.mkdir(parents=True, exist_ok=True)
    (args.out / "fleet.md").write_text(text)
    draw(runs, bounds, args.maps, args.agents, args.out / "fleet.png")
    print(text)
    print(f"wrote {args.out / 'fleet.md'} and {args.out / 'fleet.png'}", file=sys.stderr)
    return 0


def run_all(
    args: argparse.Namespace, bounds: dict[tuple[str, int], Bound | None]
) -> list[FleetRun]:
    """Run every map, size and seed, `args.jobs` at a time, with a progress bar."""
    tasks = [
        (name, n, seed)
        for name in args.maps
        for n in args.agents
        if bounds[(name, n)] is not None
        for seed in range(1, args.seeds + 1)
    ]
    progress = Progress(len(tasks), "fleet")
    ports = PortPool()
    runs: list[FleetRun] = []
    pool = ThreadPoolExecutor(max_workers=args.jobs)
    try:
        vary = tuple(args.up_args) if args.up_args is not None else VARY
        if args.planning_speed is not None:
            vary += ("--planning-speed", f"{args.planning_speed:g}")
        futures = [pool.submit(run_one, *t, ports, args.timeout, vary) for t in tasks]
        for future in as_completed(futures):
            run = future.result()
            runs.append(run)
            t = f"{run.mission_time:g} s" if run.mission_time is not None else run.reason
            progress.step(f"{run.scenario} x{run.agents} seed {run.seed}: {run.result} {t}")
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        stop_all()
        raise
    pool.shutdown()
    return sorted(runs, key=lambda r: (args.maps.index(r.scenario), r.agents, r.seed))


if __name__ == "__main__":
    sys.exit(main())
