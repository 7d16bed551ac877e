"""`cbdi-planner`: plan a PDDL 2.1 problem, validate a plan, or serve an agent's planner.

    cbdi-planner plan DOMAIN PROBLEM [--timeout S] [--search auto|ff|ehc|bfs] [--anytime] [--json]
    cbdi-planner validate DOMAIN PROBLEM PLAN
    cbdi-planner serve --agent NAME --agent-file FILE ...     (the planner service)
    cbdi plan ...                                              (the same as `cbdi-planner plan`)

Exit codes: 0 solved (or valid), 2 bad input (a file that does not read or parse),
3 unsolvable, 4 timeout, 5 invalid plan.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from cbdi_planner.errors import PlanInvalid, PlannerError, Unsolvable
from cbdi_planner.grounding import ground
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.plan import Plan, parse_plan
from cbdi_planner.search import STRATEGIES, Budget, SearchStats, search
from cbdi_planner.simulate import validate
from cbdi_planner.task import Task

__all__ = ["EXIT", "main", "plan_main", "validate_main"]

EXIT = {"solved": 0, "valid": 0, "input": 2, "unsolvable": 3, "timeout": 4, "invalid": 5}

_USAGE = """usage: cbdi-planner {plan,validate,serve} ...

  plan DOMAIN PROBLEM        find a plan (the IPC plan on stdout, statistics on stderr)
  validate DOMAIN PROBLEM PLAN  check a plan by simulating it
  serve --agent A --agent-file F  run the planner service of one agent

exit codes: 0 solved/valid, 2 bad input, 3 unsolvable, 4 timeout, 5 invalid plan
"""


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch to a subcommand."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(_USAGE, end="")
        return 0 if args else 2
    command, rest = args[0], args[1:]
    if command == "plan":
        return plan_main(rest)
    if command == "validate":
        return validate_main(rest)
    if command == "serve":
        from cbdi_planner.agent.cli import main as serve_main

        return serve_main(rest)
    print(f"cbdi-planner: unknown command {command!r}\n{_USAGE}", end="", file=sys.stderr)
    return 2


def _load(domain_file: str, problem_file: str) -> tuple[Task, dict[str, float]]:
    """Parse and ground; return the task and seconds per phase."""
    phases: dict[str, float] = {}
    started = time.perf_counter()
    domain = parse_domain(_read(domain_file), domain_file)
    problem = parse_problem(_read(problem_file), domain, problem_file)
    phases["parse"] = time.perf_counter() - started
    started = time.perf_counter()
    task = ground(domain, problem)
    phases["ground"] = time.perf_counter() - started
    return task, phases


def _read(path: str) -> str:
    try:
        return Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise FileNotFoundError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise FileNotFoundError(f"{path}: not a UTF-8 text file") from None


def _plan_parser() -> argparse.ArgumentParser:
    """The command line of `cbdi plan`."""
    parser = argparse.ArgumentParser(
        prog="cbdi plan",
        description="Plan a PDDL 2.1 temporal problem with cbdi's planner.",
        epilog="exit codes: 0 solved, 2 bad input, 3 unsolvable, 4 timeout",
    )
    parser.add_argument("domain")
    parser.add_argument("problem")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds (default 60)")
    parser.add_argument("--expansions", type=int, default=None, help="node expansion budget")
    parser.add_argument(
        "--search",
        choices=STRATEGIES,
        default="auto",
        help="auto: goal agenda, then ff; ff: hill-climbing, then best-first (default auto)",
    )
    parser.add_argument(
        "--compress",
        choices=("auto", "yes", "no"),
        default="auto",
        help="search whole actions instead of their starts and ends (auto: when no "
        "concurrency is required, falling back to starts and ends)",
    )
    parser.add_argument(
        "--anytime", action="store_true", help="keep searching for shorter makespans"
    )
    parser.add_argument("--epsilon", type=float, default=0.001)
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    parser.add_argument("--output", "-o", help="also write the plan to this file")
    return parser


def plan_main(argv: Sequence[str] | None = None) -> int:
    """`cbdi plan DOMAIN PROBLEM`: print the plan; statistics to stderr or in the JSON."""
    args = _plan_parser().parse_args(argv)
    report: dict[str, Any] = {"domain": args.domain, "problem": args.problem}
    try:
        task, phases = _load(args.domain, args.problem)
    except (PlannerError, FileNotFoundError) as exc:
        return _finish(
            args, report, "unsolvable" if isinstance(exc, Unsolvable) else "input", str(exc)
        )
    report["grounded"] = {
        "facts": len(task.facts),
        "actions": len(task.actions),
        "numeric": len(task.num_vars),
    }
    improvements: list[dict[str, float]] = []

    def on_plan(plan: Plan) -> None:
        improvements.append(
            {
                "seconds": round(time.perf_counter() - t0, 4),
                "makespan": plan.makespan,
                "actions": len(plan),
            }
        )
        if args.anytime and not args.json:
            print(
                f"; plan {len(improvements)}: makespan {plan.makespan:.3f}, {len(plan)} actions",
                file=sys.stderr,
            )

    t0 = time.perf_counter()
    result = search(
        task,
        strategy=args.search,
        anytime=args.anytime,
        epsilon=args.epsilon,
        budget=Budget(args.expansions, args.timeout),
        on_plan=on_plan,
        compress={"auto": None, "yes": True, "no": False}[args.compress],
    )
    phases["search"] = time.perf_counter() - t0
    report["search"] = _search_report(result.stats)
    report["seconds"] = {k: round(v, 4) for k, v in phases.items()}
    report["improvements"] = improvements
    if result.plan is None:
        status = "timeout" if result.status == "timeout" else "unsolvable"
        return _finish(args, report, status, _why_no_plan(args, result.status))
    plan = result.plan
    report["plan"] = [
        {"time": a.time, "action": a.name, "duration": a.duration} for a in plan.actions
    ]
    report["makespan"] = plan.makespan
    if args.output:
        Path(args.output).write_text(plan.to_ipc(), encoding="utf-8")
    if not args.json:
        sys.stdout.write(plan.to_ipc())
    return _finish(args, report, "solved", "")


def _search_report(stats: SearchStats) -> dict[str, Any]:
    """What the search did, for the report."""
    return {
        "strategy": stats.strategy,
        "expanded": stats.expanded,
        "generated": stats.generated,
        "evaluated": stats.evaluated,
        "inconsistent": stats.inconsistent,
        "plans": stats.plans,
        "compressed": stats.compressed,
    }


def _why_no_plan(args: argparse.Namespace, status: str) -> str:
    """Why a search with `status` (not solved) gave no plan."""
    why = {
        "timeout": f"no plan within the budget ({args.timeout:g} s"
        + (f", {args.expansions} expansions)" if args.expansions else ")"),
        "unsolvable": "the search space is exhausted: no plan exists",
        "incomplete": "enforced hill-climbing got stuck (try --search auto or bfs)",
    }
    return why.get(status, status)


def _finish(args: argparse.Namespace, report: dict[str, Any], status: str, error: str) -> int:
    report["status"] = status
    if error:
        report["error"] = error
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        if error:
            print(f"cbdi plan: {status}: {error}", file=sys.stderr)
        if "grounded" in report:
            g, s = report["grounded"], report.get("search", {})
            secs = " ".join(f"{k}={v:.3f}s" for k, v in report.get("seconds", {}).items())
            print(
                f"; {status}: facts={g['facts']} actions={g['actions']} "
                f"expanded={s.get('expanded', 0)} strategy={s.get('strategy', '')} "
                f"makespan={report.get('makespan', 0):.3f} {secs}",
                file=sys.stderr,
            )
    return EXIT[status]


def validate_main(argv: Sequence[str] | None = None) -> int:
    """`cbdi-planner validate DOMAIN PROBLEM PLAN`: simulate the plan; exit 0 if valid."""
    parser = argparse.ArgumentParser(
        prog="cbdi-planner validate", description="Check a plan by simulating it."
    )
    parser.add_argument("domain")
    parser.add_argument("problem")
    parser.add_argument("plan")
    parser.add_argument("--epsilon", type=float, default=0.001)
    args = parser.parse_args(argv)
    try:
        task, _ = _load(args.domain, args.problem)
        sim = validate(task, parse_plan(_read(args.plan)), epsilon=args.epsilon)
    except PlanInvalid as exc:
        print(f"{args.plan}: invalid plan: {exc}", file=sys.stderr)
        return EXIT["invalid"]
    except Unsolvable as exc:
        print(f"{args.problem}: invalid plan: the goal is unreachable ({exc})", file=sys.stderr)
        return EXIT["invalid"]
    except (PlannerError, FileNotFoundError) as exc:
        print(f"cbdi-planner validate: {exc}", file=sys.stderr)
        return EXIT["input"]
    print(f"valid plan: makespan {sim.time:.3f}")
    return EXIT["valid"]


if __name__ == "__main__":
    sys.exit(main())
