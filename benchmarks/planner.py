"""cbdi's temporal planner against the peer planner kairos, on IPC problems and recycling maps.

Every problem under the IPC temporal suite (`--suite DIR`, env `CBDI_TEMPORAL_BENCHMARKS`,
default `../shared/benchmarks/temporal` next to the repository; never copied into it) and
every recycling problem in `domains/recycling/problems/` is planned by both planners, each
in its own process, in anytime mode, with the same limit (`--timeout`, 60 s per problem):

- cbdi: `cbdi plan D P --anytime --json -o PLAN`; its plan times are its own clock (parse
  and ground, then the search's `improvements`; the limit bounds the search);
- kairos: `kairos solve D P --anytime --threads 1 --output PLAN -v`, one search thread,
  as cbdi has one core (the machine has two); plan times from its `-v` log.

A process still running `GRACE` seconds after its limit is killed. The best plan of each
run is checked by `kairos validate` (--epsilon 0.001), an independent validator: a plan it
rejects counts as unsolved and is flagged. Makespans are the validator's. The IPC quality
score of a run is the best makespan either planner found over its own (0 if unsolved).

    .venv/bin/python benchmarks/planner.py [--timeout 60] [--only REGEX]
        [--planners cbdi,kairos] [--jobs 1] [--suite DIR] [--csv PATH] [--reuse CSV]

Prints a table and a summary against issue 3's targets and writes the table as CSV
(default `benchmarks/results/planner.csv`; plans go to `plans/` next to it).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cbdi_planner.errors import PlanInvalid
from cbdi_planner.plan import Plan, parse_plan

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
RECYCLING_DOMAIN = ROOT / "domains/recycling/pddl/domain.pddl"
RECYCLING_PROBLEMS = ROOT / "domains/recycling/problems"
DEFAULT_SUITE = ROOT.parent / "shared/benchmarks/temporal"
DEFAULT_CSV = ROOT / "benchmarks/results/planner.csv"
PLANNERS = ("cbdi", "kairos")
EPSILON = 0.001
KAIROS_THREADS = 1
GRACE = 15.0
PAPER = "recycling/recycling/paper-7x7"
PAPER_OPTIMUM = (34.0, 22)  # makespan (integer durations; epsilons add < 0.5), moves
COLUMNS = (
    "suite",
    "domain",
    "problem",
    "planner",
    "solved",
    "valid",
    "first_time",
    "first_makespan",
    "best_time",
    "best_makespan",
    "moves",
    "quality",
    "status",
    "exit",
    "wall",
)

# Exit codes of each planner, as their --help documents them.
CBDI_STATUS = {0: "solved", 2: "input", 3: "unsolvable", 4: "timeout", 5: "invalid"}
KAIROS_STATUS = {
    0: "solved",
    1: "crash",
    2: "input",
    10: "unsolvable",
    11: "timeout",
    12: "memory",
    13: "unsupported",
    14: "no-plan",
}
_KAIROS_PLAN = re.compile(r"^\[\s*([0-9.]+)s\] \[search\] plan (\d+) with", re.MULTILINE)
_VALID = re.compile(r"plan valid, makespan ([0-9.eE+-]+)")


@dataclass(frozen=True)
class Problem:
    """One planning problem: which suite and domain it belongs to, and its files."""

    suite: str
    domain: str
    name: str
    domain_file: Path
    problem_file: Path

    @property
    def key(self) -> str:
        """Return `suite/domain/problem`, the name `--only` matches."""
        return f"{self.suite}/{self.domain}/{self.name}"

    @property
    def files(self) -> list[str]:
        """Return the domain and problem files, as a planner's arguments."""
        return [str(self.domain_file), str(self.problem_file)]


@dataclass(frozen=True)
class Found:
    """A plan an anytime run reported: when (seconds, the planner's clock) and makespan."""

    seconds: float
    makespan: float


@dataclass(frozen=True)
class Outcome:
    """What a planner process left: the plans it found in order, its best plan, its end."""

    status: str
    exit: int
    wall: float
    found: tuple[Found, ...]
    plan_file: Path | None


@dataclass(frozen=True)
class Result:
    """A run judged by the validator: `makespan` and `moves` are of its best valid plan."""

    problem: Problem
    planner: str
    outcome: Outcome
    valid: bool
    makespan: float | None
    moves: int | None
    note: str = ""

    @property
    def solved(self) -> bool:
        """Return whether the run's best plan was found and validated."""
        return self.valid and self.makespan is not None


# ---------------------------------------------------------------- pure: reading outputs


def cbdi_found(report: dict[str, Any]) -> tuple[Found, ...]:
    """Read the improvements of `cbdi plan --json`; their clock starts after parse+ground."""
    seconds = report.get("seconds", {})
    prep = float(seconds.get("parse", 0.0)) + float(seconds.get("ground", 0.0))
    return tuple(
        Found(prep + float(i["seconds"]), float(i["makespan"]))
        for i in report.get("improvements", [])
    )


def kairos_times(log: str) -> list[float]:
    """Return the times of kairos's anytime plans, in order, from its `-v` log."""
    return [float(m.group(1)) for m in _KAIROS_PLAN.finditer(log)]


def moves_of(plan: Plan) -> int:
    """Count the move actions of a recycling plan."""
    return sum(1 for a in plan.actions if a.name.split()[0] == "move")


def validated_makespan(output: str) -> float | None:
    """Read the makespan `kairos validate` reports for a valid plan."""
    match = _VALID.search(output)
    return float(match.group(1)) if match else None


def reached(found: Sequence[Found], makespan: float) -> Found | None:
    """Return the first plan whose makespan is within 0.5 of `makespan` or better."""
    return next((f for f in found if f.makespan <= makespan + 0.5), None)


# ---------------------------------------------------------------- pure: scoring


def qualities(results: Iterable[Result]) -> dict[tuple[str, str], float]:
    """Score each run: the best valid makespan of its problem over its own, 0 unsolved."""
    results = list(results)
    best: dict[str, float] = {}
    for r in results:
        if r.solved and r.makespan is not None:
            best[r.problem.key] = min(best.get(r.problem.key, math.inf), r.makespan)
    return {
        (r.problem.key, r.planner): (
            best[r.problem.key] / r.makespan if r.solved and r.makespan else 0.0
        )
        for r in results
    }


def geometric_mean(values: Sequence[float]) -> float | None:
    """Return the geometric mean of positive values, None for none."""
    if not values:
        return None
    return math.exp(sum(math.log(max(v, 1e-6)) for v in values) / len(values))


def time_ratios(results: Sequence[Result], ours: str, theirs: str) -> list[float]:
    """Return our first-plan time over theirs on each problem both solve."""
    by = {(r.problem.key, r.planner): r for r in results}
    out = []
    for key in dict.fromkeys(r.problem.key for r in results):
        a, b = by.get((key, ours)), by.get((key, theirs))
        if a and b and a.solved and b.solved and a.outcome.found and b.outcome.found:
            out.append(
                max(a.outcome.found[0].seconds, 1e-3) / max(b.outcome.found[0].seconds, 1e-3)
            )
    return out


def row(result: Result, quality: float) -> dict[str, str]:
    """Return the CSV row of a run (empty cells for what it has not)."""
    found, o = result.outcome.found, result.outcome
    first, best = (found[0], found[-1]) if found else (None, None)
    makespan = result.makespan  # the validator's; else what the planner claimed
    if makespan is None and best is not None:
        makespan = best.makespan
    return {
        "suite": result.problem.suite,
        "domain": result.problem.domain,
        "problem": result.problem.name,
        "planner": result.planner,
        "solved": "yes" if result.solved else "no",
        "valid": "" if o.plan_file is None else ("yes" if result.valid else "NO"),
        "first_time": f"{first.seconds:.3f}" if first else "",
        "first_makespan": f"{first.makespan:.3f}" if first else "",
        "best_time": f"{best.seconds:.3f}" if best else "",
        "best_makespan": "" if makespan is None else f"{makespan:.3f}",
        "moves": "" if result.moves is None else str(result.moves),
        "quality": f"{quality:.3f}",
        "status": o.status + (f" ({result.note})" if result.note else ""),
        "exit": str(o.exit),
        "wall": f"{o.wall:.2f}",
    }


# ---------------------------------------------------------------- pure: report


def table(rows: Sequence[dict[str, str]]) -> str:
    """Format the rows as an aligned text table."""
    shown = [c for c in COLUMNS if c not in ("suite", "domain", "valid")]
    lines = [
        [f"{r['domain']}/{r['problem']}" if c == "problem" else r[c] for c in shown] for r in rows
    ]
    widths = [max(len(x) for x in col) for col in zip(shown, *lines, strict=True)]
    return "\n".join(
        "  ".join(x.ljust(w) for x, w in zip(cells, widths, strict=True)).rstrip()
        for cells in [shown, *lines]
    )


def summary(results: Sequence[Result], planners: Sequence[str], timeout: float) -> str:
    """Summarise solved counts, quality scores, time ratio and the 7x7 targets."""
    q = qualities(results)
    lines = [f"limit {timeout:g} s per problem; kairos with --threads {KAIROS_THREADS}"]
    for suite in sorted({r.problem.suite for r in results}):
        total = len({r.problem.key for r in results if r.problem.suite == suite})
        counts = ", ".join(
            f"{p} {sum(r.solved for r in results if r.planner == p and r.problem.suite == suite)}"
            f"/{total}"
            for p in planners
        )
        lines.append(f"solved with valid plans, {suite}: {counts}")
    suite_of = {r.problem.key: r.problem.suite for r in results}
    for suite in sorted(set(suite_of.values())):
        score = {
            p: sum(v for (key, pl), v in q.items() if pl == p and suite_of[key] == suite)
            for p in planners
        }
        lines.append(
            f"quality score (IPC), {suite}: " + ", ".join(f"{p} {s:.2f}" for p, s in score.items())
        )
        ours, theirs = PLANNERS
        if set(PLANNERS) <= set(planners) and score[theirs]:
            ratio = score[ours] / score[theirs]
            target = (
                f" (target >= 0.9: {'met' if ratio >= 0.9 else 'missed'})" if suite == "ipc" else ""
            )
            lines.append(f"quality ours/kairos, {suite}: {ratio:.3f}{target}")
    if set(PLANNERS) <= set(planners):
        ours, theirs = PLANNERS
        ratios = time_ratios(results, ours, theirs)
        mean = geometric_mean(ratios)
        if mean is not None:
            lines.append(
                f"first-plan time ours/kairos, geometric mean over {len(ratios)} "
                f"problems both solve: {mean:.2f}x"
            )
    lines += [paper_line(r) for r in results if r.problem.key == PAPER]
    bad = [f"{r.planner} {r.problem.key}" for r in results if r.outcome.plan_file and not r.valid]
    lines.append("invalid plans: " + (", ".join(bad) if bad else "none"))
    return "\n".join(lines)


def paper_line(result: Result) -> str:
    """Say where a run on the paper's 7x7 map stands (first plan, anytime optimum)."""
    found = result.outcome.found
    if not found or not result.solved:
        return f"7x7 {result.planner}: no valid plan ({result.outcome.status})"
    best = reached(found, PAPER_OPTIMUM[0])
    optimum = f"makespan <= 34 at {best.seconds:.3f} s" if best else "makespan 34 not reached"
    return (
        f"7x7 {result.planner}: first plan {found[0].seconds:.3f} s (makespan "
        f"{found[0].makespan:.3f}); {optimum}; best plan {result.moves} moves, makespan "
        f"{result.makespan:.3f}"
    )


# ---------------------------------------------------------------- shell: processes


def problems(suite: Path | None) -> list[Problem]:
    """List the IPC problems of the suite (if any), then the recycling problems."""
    out = []
    for folder in sorted(p for p in (suite.iterdir() if suite else ()) if p.is_dir()):
        domain = folder / "domain.pddl"
        if domain.exists():
            for file in sorted(folder.glob("*.pddl")):
                if file != domain:
                    out.append(Problem("ipc", folder.name, file.stem, domain, file))
    for file in sorted(RECYCLING_PROBLEMS.glob("*.pddl"), key=_map_size):
        out.append(Problem("recycling", "recycling", file.stem, RECYCLING_DOMAIN, file))
    return out


def _map_size(path: Path) -> tuple[int, str]:
    sizes = re.findall(r"(\d+)x\d+", path.stem)
    return (int(sizes[0]) if sizes else 0, path.stem)


def execute(command: list[str], limit: float) -> tuple[int, str, str, float]:
    """Run a command; kill it after `limit` s. Return exit (-9 killed), out, err, wall."""
    started = time.perf_counter()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=limit)
    except subprocess.TimeoutExpired as exc:
        return -9, _text(exc.stdout), _text(exc.stderr), time.perf_counter() - started
    return done.returncode, done.stdout, done.stderr, time.perf_counter() - started


def _text(data: str | bytes | None) -> str:
    return data.decode(errors="replace") if isinstance(data, bytes) else data or ""


def run_cbdi(problem: Problem, timeout: float, plan_file: Path) -> Outcome:
    """Plan with cbdi in anytime mode; its plan file holds its best plan."""
    plan_file.unlink(missing_ok=True)
    flags = f"--timeout {timeout:g} --anytime --json --epsilon {EPSILON:g} -o".split()
    command = [str(BIN / "cbdi"), "plan", *problem.files, *flags, str(plan_file)]
    code, out, err, wall = execute(command, timeout + GRACE)
    try:
        report = json.loads(out)
    except json.JSONDecodeError:
        status = "killed" if code == -9 else f"crash: {err.strip()[-200:]}"
        return Outcome(status, code, wall, (), None)
    status = str(report.get("status", CBDI_STATUS.get(code, "crash")))
    found = cbdi_found(report)
    return Outcome(status, code, wall, found, plan_file if plan_file.exists() else None)


def run_kairos(problem: Problem, timeout: float, plan_file: Path) -> Outcome:
    """Plan with kairos in anytime mode; its plans are PLAN.1, PLAN.2, ... (best last)."""
    for old in plan_file.parent.glob(plan_file.name + ".*"):
        old.unlink()
    flags = f"--timeout {timeout:g} --anytime --threads {KAIROS_THREADS} --epsilon {EPSILON:g}"
    command = [str(BIN / "kairos"), "solve", *problem.files, *flags.split()]
    command += ["--output", str(plan_file), "-v"]
    code, _, err, wall = execute(command, timeout + GRACE)
    files = sorted(plan_file.parent.glob(plan_file.name + ".*"), key=lambda p: int(p.suffix[1:]))
    times = kairos_times(err) + [wall] * len(files)  # a killed run may miss log lines
    found = []
    for seconds, file in zip(times, files, strict=False):
        try:
            found.append(Found(seconds, parse_plan(file.read_text()).makespan))
        except PlanInvalid:
            found.append(Found(seconds, math.inf))
    status = "killed" if code == -9 else KAIROS_STATUS.get(code, f"exit {code}")
    return Outcome(status, code, wall, tuple(found), files[-1] if files else None)


def judge(problem: Problem, planner: str, outcome: Outcome) -> Result:
    """Validate the best plan of a run with `kairos validate`."""
    if outcome.plan_file is None:
        return Result(problem, planner, outcome, False, None, None)
    command = [str(BIN / "kairos"), "validate", *problem.files, str(outcome.plan_file)]
    command += ["--epsilon", f"{EPSILON:g}"]
    code, out, err, _ = execute(command, 120.0)
    makespan = validated_makespan(out + err) if code == 0 else None
    try:
        plan: Plan | None = parse_plan(outcome.plan_file.read_text())
    except PlanInvalid:
        plan = None
    moves = moves_of(plan) if plan is not None and problem.suite == "recycling" else None
    if makespan is None:
        why = next((x for x in (out + err).splitlines() if "error" in x), "rejected")
        return Result(problem, planner, outcome, False, None, moves, f"INVALID: {why[:120]}")
    return Result(problem, planner, outcome, True, makespan, moves)


RUNNERS: dict[str, Callable[[Problem, float, Path], Outcome]] = {
    "cbdi": run_cbdi,
    "kairos": run_kairos,
}


def benchmark(problem: Problem, planner: str, timeout: float, plans: Path) -> Result:
    """Plan one problem with one planner and judge the plan."""
    folder = plans / planner
    folder.mkdir(parents=True, exist_ok=True)
    plan_file = folder / f"{problem.domain}-{problem.name}.plan"
    return judge(problem, planner, RUNNERS[planner](problem, timeout, plan_file))


# ---------------------------------------------------------------- command line


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark; print the table and summary; write the CSV."""
    args = _parser().parse_args(argv)
    planners = [p.strip() for p in args.planners.split(",") if p.strip()]
    if unknown := set(planners) - set(RUNNERS):
        print(f"unknown planners: {', '.join(sorted(unknown))}", file=sys.stderr)
        return 2
    suite = Path(args.suite)
    if not suite.is_dir():
        print(
            f"IPC suite {suite} not found (--suite DIR or CBDI_TEMPORAL_BENCHMARKS): "
            "running the recycling problems only",
            file=sys.stderr,
        )
    todo = [p for p in problems(suite if suite.is_dir() else None) if re.search(args.only, p.key)]
    tasks = [(p, planner) for p in todo for planner in planners]
    # Every problem of the suite, so that `--only` re-runs part of an earlier table. The
    # earlier CSV is read first: a bad one is reported before an hour of runs, not after.
    everything = problems(suite if suite.is_dir() else None)
    reused: list[Result] = []
    if args.reuse:
        try:
            reused = reuse(Path(args.reuse), everything, {(p.key, pl) for p, pl in tasks})
        except (OSError, KeyError, ValueError) as exc:
            print(
                f"--reuse {args.reuse}: not a CSV this benchmark wrote ({exc!r})", file=sys.stderr
            )
            return 2
    load = os.getloadavg()[0]
    print(
        f"{len(todo)} problems x {len(planners)} planners, {args.timeout:g} s each, "
        f"{args.jobs} at a time, load {load:.2f} on {os.cpu_count()} cores",
        flush=True,
    )
    plans = Path(args.csv).parent / "plans"
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(benchmark, p, pl, args.timeout, plans) for p, pl in tasks]
        results = []
        for future in futures:
            results.append(future.result())
            _progress(results[-1])
    if reused:
        results += reused
        planners += sorted({r.planner for r in reused} - set(planners))
        order = {p.key: i for i, p in enumerate(everything)}
        results.sort(key=lambda r: (order[r.problem.key], PLANNERS.index(r.planner)))
    rows = write_csv(results, Path(args.csv))
    print("\n" + table(rows) + "\n")
    print(summary(results, planners, args.timeout))
    print(f"load average {load:.2f} at start, {os.getloadavg()[0]:.2f} at end; CSV {args.csv}")
    return 0


def _progress(result: Result) -> None:
    r = row(result, 0.0)
    print(
        f"{result.problem.key:36} {result.planner:7} solved={r['solved']:3} "
        f"first={r['first_time'] or '-':>8} best={r['best_makespan'] or '-':>10} "
        f"{r['status']}",
        flush=True,
    )


def reuse(
    path: Path, todo: Sequence[Problem], skip: Sequence[str] | set[tuple[str, str]]
) -> list[Result]:
    """Read back the runs of an earlier CSV, except those redone now (`skip`).

    `skip` holds planners, or `(problem key, planner)` pairs. Only problems in `todo`
    are kept; a run keeps its first and best plans (time and makespan), its verdict
    and its status, which is all scoring and the summary read.
    """
    by_key = {p.key: p for p in todo}
    out = []
    with path.open(newline="", encoding="utf-8") as handle:
        for r in csv.DictReader(handle):
            key = f"{r['suite']}/{r['domain']}/{r['problem']}"
            problem, planner = by_key.get(key), r["planner"]
            redone = planner in skip or (key, planner) in skip
            if problem is None or redone or planner not in PLANNERS:
                continue
            found = tuple(
                Found(float(r[f"{k}_time"]), float(r[f"{k}_makespan"] or r["best_makespan"]))
                for k in ("first", "best")
                if r[f"{k}_time"]
            )
            solved = r["solved"] == "yes"
            outcome = Outcome(r["status"], int(r["exit"] or 0), float(r["wall"] or 0), found, None)
            out.append(
                Result(
                    problem,
                    r["planner"],
                    outcome,
                    valid=solved,
                    makespan=float(r["best_makespan"]) if solved else None,
                    moves=int(r["moves"]) if r["moves"] else None,
                    note=f"from {path.name}",
                )
            )
    return out


def write_csv(results: Sequence[Result], path: Path) -> list[dict[str, str]]:
    """Write the rows of the results to a CSV file and return them."""
    q = qualities(results)
    rows = [row(r, q[(r.problem.key, r.planner)]) for r in results]
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as out:
        writer = csv.DictWriter(out, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    return rows


# ---------------------------------------------------------------- arguments


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per problem")
    parser.add_argument("--only", default="", help="regex on suite/domain/problem")
    parser.add_argument("--planners", default=",".join(PLANNERS), help="cbdi,kairos")
    parser.add_argument("--jobs", type=int, default=1, help="runs at once (default 1)")
    parser.add_argument(
        "--suite",
        default=os.environ.get("CBDI_TEMPORAL_BENCHMARKS", str(DEFAULT_SUITE)),
        help="IPC temporal problems: DOMAIN/domain.pddl and DOMAIN/pNN.pddl",
    )
    parser.add_argument("--csv", default=str(DEFAULT_CSV), help="where to write the table")
    parser.add_argument(
        "--reuse",
        default="",
        help="an earlier CSV: its runs not redone now join the table and the scores "
        "(re-measure cbdi against a kept kairos run, or re-run part of a table with --only)",
    )
    return parser


if __name__ == "__main__":
    sys.exit(main())
