"""Online (continual) against offline (plan, then act) on a family of generated maps.

Table I measures one map, the paper's. This runs the same comparison on maps nobody
wrote: `cbdi map --seed S` for S in 1..N (random walls with every free cell reachable, a
bin reachable through a single access cell, a person's loop crossing it, litter and
people placed by the seed), each map with its lockstep BDI scenario, once per mode with
`--agents` robots. Runs are paired by map: the difference online - offline of mission
time (simulated s) and of moves, with 95% bootstrap intervals of the mean
(`table1_stats`), and which runs did not recycle everything.

    .venv/bin/python benchmarks/generated.py [--maps 20] [--agents 1] [--size 9x9]
        [--litter 4] [--people 2] [--jobs 2] [--planning-speed EXP_PER_S]
        [--csv benchmarks/results/generated.csv]

Virtual time: every figure is the same on any machine (a run is a function of the map,
the flags and the seed); only the wall time is this machine's.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from queue import Queue

sys.path.insert(0, str(Path(__file__).resolve().parent))

from table1_runner import execute
from table1_stats import describe, paired_differences, verdict

ROOT = Path(__file__).resolve().parents[1]
CBDI = str(ROOT / ".venv/bin/cbdi")
MODES = ("offline", "online")


@dataclass
class Run:
    """One run's outcome (`result` done: every item recycled)."""

    map_seed: int
    agents: int
    mode: str
    result: str
    exit: int
    sim_time: float
    moves: int
    recycled: int
    improvements: int
    trace_digest: str
    wall: float


def make_map(seed: int, args: argparse.Namespace, folder: Path) -> Path:
    """Write map `seed` and its scenario; return the scenario."""
    m, s = folder / f"map{seed}.toml", folder / f"scen{seed}.toml"
    argv = [CBDI, "map", "--seed", str(seed), "--size", args.size, "--agents", str(args.agents)]
    argv += ["--litter", str(args.litter), "--people", str(args.people)]
    argv += ["-o", str(m), "--scenario", str(s)]
    code, _, err, _ = execute(argv, 120)
    if code != 0:
        raise SystemExit(f"cbdi map --seed {seed} failed: {err.strip()}")
    return s


def run(scenario: Path, seed: int, mode: str, args: argparse.Namespace, ports: Queue[int]) -> Run:
    port = ports.get()  # a router port no other run uses now
    try:
        return _run(scenario, seed, mode, args, port)
    finally:
        ports.put(port)


def _run(scenario: Path, seed: int, mode: str, args: argparse.Namespace, port: int) -> Run:
    argv = [CBDI, "up", str(scenario), "--agents", str(args.agents), "--mode", mode]
    argv += ["--json", "--quiet", "--max-time", str(args.max_time), "--port", str(port)]
    if args.planning_speed is not None:
        argv += ["--planning-speed", str(args.planning_speed)]
    code, out, _err, wall = execute(argv, args.run_timeout)
    try:
        s = json.loads(out)
    except json.JSONDecodeError:
        return Run(seed, args.agents, mode, "crashed", code, 0.0, 0, 0, 0, "", wall)
    agents = s.get("stats", {}).get("agents", {})
    planner = s.get("planner", {}).get("total", {})
    return Run(
        seed,
        args.agents,
        mode,
        s.get("result", "?"),
        code,
        float(s.get("sim_time", 0.0)),
        sum(a.get("moves", 0) for a in agents.values()),
        sum(a.get("recycled", 0) for a in agents.values()),
        int(planner.get("improvements", 0)),
        s.get("trace_digest", ""),
        wall,
    )


def report(runs: list[Run]) -> list[str]:
    done = {m: {r.map_seed: r for r in runs if r.mode == m and r.result == "done"} for m in MODES}
    lines = [f"{len(runs)} runs; not done: " + (", ".join(
        f"map {r.map_seed} {r.mode} ({r.result})" for r in runs if r.result != "done"
    ) or "none")]  # fmt: skip
    for what, unit in (("sim_time", "mission time (simulated s)"), ("moves", "moves")):
        lines.append(f"\n{unit}:")
        for m in MODES:
            d = describe([getattr(r, what) for r in done[m].values()])
            ci = f"[{d.interval.low:.1f}, {d.interval.high:.1f}]" if d.interval else ""
            if d.mean is not None and d.sd is not None:
                lines.append(f"  {m:<8} n={d.n} mean {d.mean:.1f} ± {d.sd:.1f} {ci}")
        pairs = paired_differences(
            {s: getattr(r, what) for s, r in done["online"].items()},
            {s: getattr(r, what) for s, r in done["offline"].items()},
        )
        diff = describe([v for _, v in pairs])
        if diff.mean is not None and diff.interval is not None:
            v = verdict(diff, lower_is_better="online better", higher_is_better="offline better")
            lines.append(
                f"  online - offline: {diff.mean:+.1f} [{diff.interval.low:+.1f},"
                f" {diff.interval.high:+.1f}] (n={diff.n} paired maps): {v}"
            )
    improved = sum(1 for r in runs if r.mode == "online" and r.improvements > 0)
    online = sum(1 for r in runs if r.mode == "online")
    lines.append(f"\nonline runs with an improved plan swapped in: {improved} of {online}")
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--maps", type=int, default=20, help="map seeds 1..N")
    p.add_argument("--agents", type=int, default=1)
    p.add_argument("--size", default="9x9")
    p.add_argument("--litter", type=int, default=4)
    p.add_argument("--people", type=int, default=2)
    p.add_argument("--max-time", type=float, default=400.0)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--run-timeout", type=float, default=900.0)
    p.add_argument(
        "--planning-speed",
        type=float,
        default=None,
        help="virtual time: expansions per simulated second (default: the agent file's)",
    )
    p.add_argument("--csv", default=str(ROOT / "benchmarks/results/generated.csv"))
    args = p.parse_args(argv)
    if args.maps < 1 or args.agents < 1 or args.jobs < 1:
        p.error("--maps, --agents and --jobs must be at least 1")
    with tempfile.TemporaryDirectory() as tmp:
        scenarios = {s: make_map(s, args, Path(tmp)) for s in range(1, args.maps + 1)}
        tasks = [(s, m) for s in scenarios for m in MODES]
        ports: Queue[int] = Queue()
        for k in range(args.jobs):
            ports.put(47100 + 10 * k)
        with ThreadPoolExecutor(args.jobs) as pool:
            futures = [pool.submit(run, scenarios[s], s, m, args, ports) for s, m in tasks]
            runs = []
            for f in futures:
                r = f.result()
                runs.append(r)
                print(
                    f"map {r.map_seed:>2} {r.mode:<7} {r.result:<10} {r.sim_time:6.1f} s"
                    f" {r.moves:3d} moves ({r.wall:.0f} wall s)",
                    flush=True,
                )
    out = Path(args.csv)
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(asdict(runs[0])))
        writer.writeheader()
        writer.writerows(asdict(r) for r in runs)
    text = report(runs)
    print("\n".join(text))
    out.with_suffix(".txt").write_text(
        f"benchmarks/generated.py --maps {args.maps} --agents {args.agents} --size {args.size}"
        f" --litter {args.litter} --people {args.people}"
        + (f" --planning-speed {args.planning_speed:g}" if args.planning_speed else "")
        + "\n"
        + "\n".join(text)
        + "\n"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
