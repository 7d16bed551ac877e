"""The paper's Table I with statistics: offline against online planning, over many seeds.

Every situation of Table I (people step every 4 or 8 epochs, detection depth 1 to 3, 2
or 3 litter items known at the start) runs in both modes for seeds 1..N at each planning
speed factor (x the agent file's `[planning] planning_speed`), `--jobs` `cbdi up --json`
processes at a time, each with a router port of its own. Then one real-time run per
situation and mode (`--speed 1 --no-lockstep`; `--realtime-seeds N`: seeds 1..N), beside
the lockstep ones.

Beside the runs: the static optimum (all litter known, no people) and, per seed, the
best plan a clairvoyant planner finds (people's walk as timed initial literals).

    .venv/bin/python benchmarks/table1.py [--seeds 10] [--jobs 2] [--only '4,1,2 8,1,2']
        [--planning-speeds 0.25,1,4] [--up-arg '--flag value']... [--no-realtime]
        [--no-clairvoyant] [--csv benchmarks/results/table1.csv] [--reuse CSV]

Writes `table1.csv` (a row per run), `table1_bounds.csv`, `table1.md` (the tables, the
verdicts, a summary) and `table1.png` (mean moves with 95% intervals) beside `--csv`.
`--reuse CSV` renders the markdown and figure again from an earlier CSV (and the bounds
CSV beside it) without running anything.
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from table1_bounds import (
    Bound,
    clairvoyant_bounds,
    clairvoyant_problems,
    read_bounds,
    static_optimum,
    write_bounds,
)
from table1_figure import draw_figure
from table1_model import (
    MODES,
    SITUATIONS,
    Run,
    Situation,
    Task,
    parse_situations,
    read_csv,
    write_csv,
)
from table1_report import render_markdown
from table1_runner import (
    PortPool,
    Progress,
    UpOptions,
    agent_planning_speed,
    check_planning_speeds,
    run_all,
    run_task,
    up_argv,
    up_supports,
)
from table1_summary import rows_of, static_of

from cbdi.errors import CbdiError, ConfigError
from cbdi.launcher.scenario import find_scenario, load_scenario

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CSV = ROOT / "benchmarks/results/table1.csv"
STATIC_TIMEOUT = 10.0
REALTIME_SEED = 1

Runner = Callable[[Task], Run]
BoundMaker = Callable[[list[Task]], list[Bound]]


@dataclass(frozen=True)
class Outputs:
    """Where a table goes: the runs' CSV and, beside it, bounds, markdown and figure."""

    csv: Path

    @property
    def bounds(self) -> Path:
        return bounds_path(self.csv)

    @property
    def markdown(self) -> Path:
        return self.csv.with_suffix(".md")

    @property
    def figure(self) -> Path:
        return self.csv.with_suffix(".png")


def bounds_path(csv: Path) -> Path:
    """Return the bounds CSV kept beside a runs CSV."""
    return csv.with_name(csv.stem + "_bounds.csv")


def tasks_of(
    situations: Sequence[Situation],
    seeds: int,
    factors: Sequence[float],
    realtime: bool,
    realtime_seeds: int = 1,
) -> list[Task]:
    """Return every lockstep task, then the real-time ones (factor 1, seeds 1..
    `realtime_seeds`)."""
    tasks = [
        Task(s, mode, seed, factor)
        for factor in factors
        for s in situations
        for mode in MODES
        for seed in range(1, seeds + 1)
    ]
    if realtime:
        tasks += [
            Task(s, mode, seed, 1.0, "realtime")
            for s in situations
            for mode in MODES
            for seed in range(REALTIME_SEED, REALTIME_SEED + realtime_seeds)
        ]
    return sorted(tasks, key=lambda t: t.sort_key())


def render(runs: Sequence[Run], bounds: Sequence[Bound], out: Outputs) -> str:
    """Write the markdown and the figure of the runs; return the markdown."""
    text = render_markdown(runs, bounds)
    out.markdown.parent.mkdir(parents=True, exist_ok=True)
    out.markdown.write_text(text, encoding="utf-8")
    draw_figure(rows_of(runs, bounds), static_of(bounds), out.figure)
    return text


def make_bounds(
    tasks: list[Task], *, map_path: Path, options: UpOptions, args: argparse.Namespace
) -> list[Bound]:
    """Compute the static optimum and (unless --no-clairvoyant) the clairvoyant bounds.

    A clairvoyant world that cannot be built is no reason to lose the runs: the column
    is left out, with the reason in the table.
    """
    bounds = [static_optimum(map_path, STATIC_TIMEOUT)]
    if not args.clairvoyant:
        return [*bounds, _skipped("--no-clairvoyant")]
    cases: dict[tuple[int, int], list[str]] = {}
    for t in tasks:
        if t.clock == "lockstep":  # the people's walk hangs on the pace and the seed only
            cases.setdefault((t.situation.move_step, t.seed), up_argv(t, options, 0)[2:])
    try:
        texts = clairvoyant_problems(cases)
    except (CbdiError, ValueError, StopIteration, SystemExit, TypeError, AttributeError) as exc:
        print(f"clairvoyant column left out: {exc!r}", file=sys.stderr)
        return [*bounds, _skipped(f"its world could not be built ({exc!r})")]
    progress = Progress(len(set(texts.values())), "clairvoyant")
    bounds += clairvoyant_bounds(
        texts, timeout=args.clairvoyant_timeout, jobs=args.jobs, step=progress.step
    )
    return bounds


def _skipped(reason: str) -> Bound:
    return Bound("clairvoyant", None, None, None, None, "skipped", note=reason)


def reuse(args: argparse.Namespace, out: Outputs) -> int:
    """Render the tables again from an earlier CSV (and its bounds CSV), running nothing."""
    path = Path(args.reuse)
    try:
        runs = read_csv(path)
        bounds = read_bounds(bounds_path(path)) if bounds_path(path).is_file() else []
    except (OSError, KeyError, ValueError, TypeError) as exc:
        print(f"--reuse {path}: not a CSV this benchmark wrote ({exc!r})", file=sys.stderr)
        return 2
    if args.only:
        runs = [r for r in runs if r.task.situation in args.only]
    sys.stdout.write(render(runs, bounds, out))
    print(f"markdown {out.markdown}, figure {out.figure} (from {path})", file=sys.stderr)
    return 0


def benchmark(
    args: argparse.Namespace,
    out: Outputs,
    runner: Runner | None = None,
    bound_maker: BoundMaker | None = None,
) -> int:
    """Run every task and the bounds, write the CSVs, render; `runner` replaces cbdi up."""
    situations = args.only or SITUATIONS
    tasks = tasks_of(
        situations, args.seeds, args.planning_speeds, args.realtime, args.realtime_seeds
    )
    if runner is None or bound_maker is None:
        try:
            runner, bound_maker = _real(args)
        except (ConfigError, ValueError) as exc:
            print(f"table1: {exc}", file=sys.stderr)
            return 2
    lockstep = [t for t in tasks if t.clock == "lockstep"]
    realtime = [t for t in tasks if t.clock == "realtime"]
    print(
        f"{len(lockstep)} lockstep runs + {len(realtime)} real-time runs, {args.jobs} at a "
        f"time, load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores",
        file=sys.stderr,
    )
    bounds = bound_maker(lockstep)
    write_bounds(bounds, out.bounds)
    runs = run_all(lockstep, runner, args.jobs, Progress(len(lockstep), "lockstep"))
    write_csv(runs, out.csv)  # kept even if the real-time runs are interrupted
    if realtime:
        runs += run_all(realtime, runner, args.jobs, Progress(len(realtime), "real time"))
        write_csv(runs, out.csv)
    sys.stdout.write(render(read_csv(out.csv), read_bounds(out.bounds), out))
    print(f"CSV {out.csv}, markdown {out.markdown}, figure {out.figure}", file=sys.stderr)
    return 0


def _real(args: argparse.Namespace) -> tuple[Runner, BoundMaker]:
    """Return the runner and bound maker that call `cbdi up` and `cbdi plan`."""
    scenario = load_scenario(find_scenario(args.scenario))
    agent = next((a for a in scenario.agents if a.agent_file is not None), None)
    default = agent_planning_speed(agent.agent_file if agent else None)
    supported = up_supports("--planning-speed")
    problem = check_planning_speeds(args.planning_speeds, default, supported)
    if problem:
        raise ValueError(problem)
    options = UpOptions(
        scenario=args.scenario,
        up_args=tuple(args.up_args),
        default_speed=default,
        pass_speed=supported and default is not None,
        run_timeout=args.run_timeout,
        lockstep_speed=args.speed,
    )
    assert scenario.map_path is not None  # the recycling grid's scenarios have a map
    maker = partial(make_bounds, map_path=scenario.map_path, options=options, args=args)
    return partial(run_task, options=options, ports=PortPool()), maker


# ---------------------------------------------------------------- arguments


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def _speed(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def _factors(text: str) -> tuple[float, ...]:
    values = tuple(_positive_float(p) for p in text.replace(",", " ").split())
    if not values:
        raise argparse.ArgumentTypeError("no planning speed factor given")
    return tuple(sorted(set(values)))


def _situations(text: str) -> tuple[Situation, ...]:
    try:
        return parse_situations(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _up_arg(text: str) -> list[str]:
    try:
        return shlex.split(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"cannot split {text!r}: {exc}") from None


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--seeds", type=_positive_int, default=10, help="seeds 1..N (default 10)")
    p.add_argument(
        "--jobs",
        type=_positive_int,
        default=os.cpu_count() or 1,
        help="runs at once (default: the number of cores)",
    )
    p.add_argument(
        "--planning-speeds",
        type=_factors,
        default=(0.25, 1.0, 4.0),
        help="factors of the agent file's planning_speed (default 0.25,1,4)",
    )
    p.add_argument("--only", type=_situations, default=(), help="situations, e.g. '4,1,2 8,1,2'")
    p.add_argument(
        "--up-arg",
        dest="up_args",
        type=_up_arg,
        action="extend",
        default=[],
        help="passed to every `cbdi up` (repeat; --up-arg '--option people_jitter=2', "
        "--up-arg=--flag)",
    )
    p.add_argument(
        "--realtime",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also one real-time run per situation and mode (default on)",
    )
    p.add_argument(
        "--realtime-seeds",
        type=_positive_int,
        default=1,
        help="real-time runs per situation and mode, seeds 1..N (default 1)",
    )
    p.add_argument(
        "--clairvoyant",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="compute the clairvoyant bound (default on)",
    )
    p.add_argument(
        "--clairvoyant-timeout",
        type=_positive_float,
        default=30.0,
        help="planning seconds per clairvoyant problem (default 30)",
    )
    p.add_argument(
        "--run-timeout",
        type=_positive_float,
        default=900.0,
        help="wall seconds per `cbdi up` (default 900)",
    )
    p.add_argument(
        "--speed",
        type=_speed,
        default=0.0,
        help="simulated s per wall s of the lockstep runs (default 0: flat out; in virtual "
        "time the run is the same at any speed, its trace digest says so)",
    )
    p.add_argument("--scenario", default="paper-7x7", help="scenario (default paper-7x7)")
    p.add_argument("--csv", type=Path, default=DEFAULT_CSV, help="the runs' CSV (outputs beside)")
    p.add_argument("--reuse", default="", help="render again from an earlier CSV, run nothing")
    return p


def main(
    argv: Sequence[str] | None = None,
    runner: Runner | None = None,
    bound_maker: BoundMaker | None = None,
) -> int:
    """Run (or with --reuse re-render) Table I; exit 2 on bad arguments."""
    args = _parser().parse_args(argv)
    out = Outputs(args.csv)
    if args.reuse:
        return reuse(args, out)
    return benchmark(args, out, runner, bound_maker)


if __name__ == "__main__":
    sys.exit(main())
