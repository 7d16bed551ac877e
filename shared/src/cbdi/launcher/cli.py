"""`cbdi up SCENARIO`: the launcher's command line."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
from collections.abc import Sequence
from dataclasses import replace

import uvloop

from cbdi import keys
from cbdi.errors import ConfigError
from cbdi.launcher.preflight import check_services
from cbdi.launcher.process import RESTART_POLICIES, RestartPolicy
from cbdi.launcher.run import LaunchOptions, RunSummary, launch
from cbdi.launcher.scenario import (
    AGENT_KINDS,
    Scenario,
    check_performed,
    check_ranges,
    check_until,
    find_scenario,
    load_scenario,
)
from cbdi.launcher.services import plan_services
from cbdi.launcher.watch import TICK
from cbdi.runtime.fault import parse_faults
from cbdi.simulator import load_simulator, parse_option_pairs, read_options

__all__ = ["check_faults", "main", "scenario_arguments", "scenario_from_args"]

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INCOMPLETE, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
PLANNER_COUNTS = ("plans", "replans", "forecast_repairs", "improvements", "search_rounds")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cbdi up",
        description="Run a scenario: a Zenoh router, the world and every agent's services as "
        "separate processes. Exit codes: 0 run ended as asked, 1 a service failed, "
        "2 bad usage or scenario, 3 the time limit came before the world was done, "
        "130 interrupted (Ctrl-C).",
    )
    scenario_arguments(p)
    return _run_arguments(p)


def scenario_arguments(p: argparse.ArgumentParser) -> None:
    """Add the scenario and the flags that override its run settings (`cbdi up`, `cbdi
    compose`); `scenario_from_args` reads them back."""
    p.add_argument("scenario", help="scenario name (domains/DOMAIN/scenarios/NAME.toml) or a file")
    p.add_argument("--agents", type=int, help="number of agents (default: the scenario's)")
    p.add_argument("--speed", type=float, help="simulated seconds per wall second")
    p.add_argument("--seed", type=int, help="seed of the world's random generator")
    p.add_argument("--until", help="'done' (the world's goals met) or simulated SECONDS")
    p.add_argument("--max-time", type=float, help="simulated seconds before a 'done' run gives up")
    p.add_argument(
        "--lockstep",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="advance an epoch only once every agent acknowledged the last one",
    )
    p.add_argument(
        "--option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="set an option of the scenario's simulator (its [world] table), e.g. "
        "--option people_jitter=1; an unknown one is refused with the list of known ones",
    )
    p.add_argument(
        "--mode",
        choices=("online", "offline"),
        help="BDI agents plan online (continual planning) or offline (plan, then act)",
    )
    p.add_argument(
        "--planning-speed",
        type=float,
        help="virtual time (lockstep): planner expansions per simulated second "
        "(default: each agent file's planning_speed)",
    )


def _run_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout at the end")
    p.add_argument(
        "--view",
        choices=("none", "text"),
        default="none",
        help="show the world every epoch (text: a character grid)",
    )
    p.add_argument(
        "--restart",
        choices=RESTART_POLICIES,
        default="on-failure",
        help="restart policy of crashed services",
    )
    p.add_argument("--max-restarts", type=int, default=3, help="restarts per service at most")
    p.add_argument("--port", type=int, default=0, help="router port (default: a free one)")
    p.add_argument("--startup-timeout", type=float, default=30.0, help="seconds to become alive")
    p.add_argument("--timeout", type=float, default=0.0, help="wall-clock limit in seconds")
    p.add_argument("--quiet", action="store_true", help="do not echo the services' logs")
    p.add_argument(
        "--delay",
        action="append",
        default=[],
        metavar="SERVICE=SECONDS",
        help="start a service (e.g. robot1/scheduler) late, to try another start order",
    )
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="SERVICE:KIND@EPOCH",
        help="inject a fault: SERVICE (world, robot1/planner, router, ...) is killed "
        "(kill: SIGKILL) or frozen (stop: SIGSTOP) as the world's epoch EPOCH reaches it, "
        "in its first life only; repeatable (docs/faults.md)",
    )
    _supervision_arguments(p)
    p.add_argument(
        "--secure",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="authenticate every service and let each do only its own part (default; "
        "docs/security.md); --no-secure: any local client may do anything",
    )
    p.add_argument(
        "--run-dir",
        metavar="DIR",
        default="",
        help="where the run's credentials go (mode 0600; default: found again from the "
        "router's port, so that `cbdi ctl --connect` finds the operator's)",
    )
    p.add_argument(
        "--record",
        metavar="FILE",
        default="",
        help="record every message of the run to an MCAP file (needs cbdi-monitor)",
    )
    return p


def _supervision_arguments(p: argparse.ArgumentParser) -> None:
    """How `cbdi up` watches its processes: heartbeats, freezes, niceness, processes."""
    p.add_argument(
        "--heartbeat",
        type=float,
        default=0.5,
        metavar="SECONDS",
        help="wall seconds between each service's heartbeats (0: none, no freeze watchdog)",
    )
    p.add_argument(
        "--freeze-limit",
        type=float,
        default=2.0,
        metavar="SECONDS",
        help="a service silent this long is frozen: reported (default 2)",
    )
    p.add_argument(
        "--freeze-kill",
        type=float,
        default=None,
        metavar="SECONDS",
        help="a frozen service still silent this long is killed and restarted by policy "
        "(default 10 in real time; in lockstep the members' ack timeout, CBDI_ACK_TIMEOUT "
        "or 120: the world waits that long for a silent member anyway, and a kill before "
        "would make the run depend on the machine's load; at least --freeze-limit)",
    )
    p.add_argument(
        "--agent-nice",
        type=int,
        default=5,
        metavar="N",
        help="run the agents' processes at niceness N (0 to 19; default 5), the router, "
        "world and monitor at cbdi up's: on a machine short of CPU the bus and the world "
        "keep pace and the robots slow down",
    )
    p.add_argument(
        "--agent-process",
        action="store_true",
        help="run each BDI agent's planner, scheduler and executor in one process "
        "(`cbdi agent`): about half the memory per robot",
    )


def scenario_from_args(args: argparse.Namespace) -> Scenario:
    """Return the scenario named by `args`, its run settings overridden by their flags.

    Raises `ConfigError` naming the flag of a bad value."""
    scenario = load_scenario(find_scenario(args.scenario))
    run = scenario.run
    if args.until is not None:
        run = replace(run, until=check_until(args.until, "--until", "until"))
    for name in ("speed", "seed", "max_time", "lockstep", "mode", "planning_speed"):
        value = getattr(args, name)
        if value is not None:
            run = replace(run, **{name: value})
    if not math.isfinite(run.speed) or run.speed < 0 or (run.speed == 0 and not run.lockstep):
        raise ConfigError("--speed", "speed", "must be > 0 (0, flat out, only with --lockstep)")
    if not math.isfinite(run.planning_speed) or run.planning_speed < 0:
        raise ConfigError("--planning-speed", "planning_speed", "must be a finite number > 0")
    problems = check_ranges(run)
    if problems:
        field, reason = problems[0]
        raise ConfigError(f"--{field.replace('_', '-')}", field, reason)
    if args.option:
        simulator = load_simulator(run.simulator, "--option")
        given = parse_option_pairs(args.option, "--option")
        options = read_options(simulator, {**scenario.options, **given}, "--option")
        scenario = replace(scenario, options=options)
        check_performed(scenario)
    scenario = replace(scenario, run=run)
    scenario = scenario.with_agents(args.agents) if args.agents else scenario
    if not any(a.kind == "bdi" for a in scenario.agents):
        for flag, value in (("--mode", args.mode), ("--planning-speed", args.planning_speed)):
            if value is not None:
                raise ConfigError(
                    flag,
                    scenario.name,
                    "the scenario has no BDI agent (only scripted ones), so nothing plans; "
                    "pick a BDI scenario (the -bdi ones and paper-7x7)",
                )
    return scenario


def _delays(entries: Sequence[str], scenario: Scenario) -> dict[str, float]:
    """Parse `--delay SERVICE=SECONDS` entries; every service must be one of the run's."""
    services = {keys.service_id(c, a.name) for a in scenario.agents for c in AGENT_KINDS[a.kind]}
    delays: dict[str, float] = {}
    for entry in entries:
        service, _, value = entry.partition("=")
        try:
            seconds = float(value)
        except ValueError:
            seconds = -1.0
        if service not in services or not (0 <= seconds <= 600):
            known = ", ".join(sorted(services))
            raise ConfigError(
                "--delay", entry, f"expected SERVICE=SECONDS (0..600), SERVICE one of {known}"
            )
        delays[service] = seconds
    return delays


def check_faults(entries: Sequence[str], scenario: Scenario, record: str = "") -> str:
    """Parse `--fault` entries against the run's services; return them as `CBDI_FAULT`
    says them ('' for none). ConfigError names the entry and the known services."""
    try:
        faults = parse_faults(entries)
    except ValueError as exc:
        raise ConfigError("--fault", ",".join(entries), str(exc)) from None
    services = {p.service for p in plan_services(scenario, "tcp/127.0.0.1:0", record)}
    for fault in faults:
        if fault.service not in services:
            known = ", ".join(sorted(services))
            reason = f"no such service in this run (known: {known})"
            raise ConfigError("--fault", str(fault), reason)
    return ",".join(map(str, faults))


def _check_liveness(heartbeat: float, limit: float) -> None:
    """Refuse a heartbeat the freeze limit could not hear twice (or non-finite values)."""
    if not (math.isfinite(heartbeat) and heartbeat >= 0):
        raise ConfigError("--heartbeat", str(heartbeat), "must be a finite number >= 0")
    if heartbeat > 0 and not (math.isfinite(limit) and limit >= 2 * heartbeat + TICK):
        raise ConfigError(
            "--freeze-limit", str(limit), f"must be at least twice --heartbeat plus {TICK} s"
        )


FREEZE_KILL = 10.0  # wall s: a frozen service silent this long is killed (real time)
ACK_TIMEOUT = 120.0  # wall s: the lockstep members' default (`ack_timeout`)


def _freeze_kill(given: float | None, lockstep: bool) -> float:
    """The kill limit: `given`, else 10 s in real time and, in lockstep, the members' ack
    timeout (what the services read from `CBDI_ACK_TIMEOUT`, 120 s by default).

    In lockstep a silent member holds its epoch until the ack timeout whatever the
    watchdog does: killed sooner, a member only starved on a loaded machine restarts and
    the run depends on the load (16 robots with 100 other processes on 2 cores: 20
    services killed and restarted, a run unlike the same run on a quiet machine).
    """
    if given is not None:
        return given
    if not lockstep:
        return FREEZE_KILL
    raw = os.environ.get("CBDI_ACK_TIMEOUT", "")
    try:
        ack = float(raw) if raw.strip() else ACK_TIMEOUT
    except ValueError:
        raise ConfigError("CBDI_ACK_TIMEOUT", raw, "must be a number of seconds") from None
    return ack if math.isfinite(ack) and ack > 0 else ACK_TIMEOUT


def _say_factory(quiet: bool) -> object:
    def say(service: str, line: str) -> None:
        if quiet and service != "launcher":
            return
        sys.stderr.write(f"{service:<18}| {line}\n")
        sys.stderr.flush()

    return say


def main(argv: Sequence[str] | None = None) -> int:
    """Run `cbdi up` and return its exit code."""
    args = _parser().parse_args(list(argv) if argv is not None else None)
    try:
        scenario = scenario_from_args(args)
        policy = RestartPolicy(mode=args.restart, max_restarts=args.max_restarts)
    except (ConfigError, ValueError) as exc:
        print(f"cbdi up: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        delays = _delays(args.delay, scenario)
        faults = check_faults(args.fault, scenario, args.record)
        _check_liveness(args.heartbeat, args.freeze_limit)
        if not 0 <= args.agent_nice <= 19:
            raise ConfigError("--agent-nice", str(args.agent_nice), "must be 0 to 19")
        freeze_kill = _freeze_kill(args.freeze_kill, scenario.run.lockstep)
        if not (math.isfinite(freeze_kill) and freeze_kill >= args.freeze_limit):
            raise ConfigError(
                "--freeze-kill", str(freeze_kill), "must be finite and >= --freeze-limit"
            )
        check_services(scenario)  # last: it builds every service (the slowest check)
    except ConfigError as exc:
        print(f"cbdi up: {exc}", file=sys.stderr)
        return EXIT_USAGE
    opts = LaunchOptions(
        delays=delays,
        restart=policy,
        port=args.port,
        startup_timeout=args.startup_timeout,
        wall_timeout=args.timeout,
        view=args.view,
        quiet=args.quiet,
        record=args.record,
        heartbeat=args.heartbeat,
        freeze_limit=args.freeze_limit,
        freeze_kill=freeze_kill,
        agent_process=args.agent_process,
        agent_nice=args.agent_nice,
        secure=args.secure,
        run_dir=args.run_dir,
        faults=faults,
    )
    say = _say_factory(args.quiet)
    summary: RunSummary = uvloop.run(launch(scenario, opts, say))  # type: ignore[arg-type]
    _report(summary, args.json)
    if summary.ok:
        return EXIT_OK
    if summary.result == "interrupted":
        return EXIT_INTERRUPTED
    return EXIT_INCOMPLETE if summary.result == "incomplete" else EXIT_FAILED


def _report(summary: RunSummary, as_json: bool) -> None:
    if as_json:
        print(json.dumps(dataclasses.asdict(summary), indent=2))
        return
    line = f"run {summary.result}"
    if summary.reason:
        line += f" ({summary.reason})"
    line += f": {summary.epochs} epochs, {summary.sim_time:.1f} simulated s, "
    line += f"{summary.wall_time:.1f} wall s; trace {summary.trace_digest[:12]}"
    print(line, file=sys.stderr)
    for member, epochs in summary.stalls.items():
        print(f"  {member}: missed the ack timeout in {epochs} epochs", file=sys.stderr)
    late = summary.lateness
    if late:
        print(
            f"  epochs late (wall s): median {late['median']} p95 {late['p95']} max "
            f"{late['max']}; {late['over']} of {late['epochs']} over {late['bound']}",
            file=sys.stderr,
        )
    frozen = {s: n for s, n in summary.freezes.items() if n}
    if frozen:
        killed = {s: n for s, n in summary.freeze_kills.items() if n}
        print(f"  frozen (reported): {frozen}; killed: {killed or 'none'}", file=sys.stderr)
    if summary.memory:
        print(f"  memory: peak {summary.memory['peak_total_mb']} MB in all", file=sys.stderr)
    for name, counts in summary.stats.get("agents", {}).items():
        text = " ".join(f"{k}={v}" for k, v in counts.items() if v)  # what happened
        acts = summary.actions.get(name)
        if acts:
            text += f" actions={acts['actions']} first_action_at={acts['first_action']}"
        done = summary.performed.get(name)
        if done:
            text += " performed=" + ",".join(f"{a}:{n}" for a, n in sorted(done.items()))
        print(f"  {name}: {text}", file=sys.stderr)
    planners = summary.planner.get("agents", {})
    rows = [*planners.items(), ("total", summary.planner.get("total", {}))] if planners else []
    for name, counts in rows:
        text = " ".join(f"{k}={counts[k]}" for k in PLANNER_COUNTS)
        print(f"  {name} planner: {text}", file=sys.stderr)
