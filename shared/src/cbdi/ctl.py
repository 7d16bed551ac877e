"""`cbdi ctl`: the operator's command line for running agents.

    cbdi ctl show robot1 [--watch 1] [--no-beliefs] [--json]
    cbdi ctl desire add robot1 visit "(in robot1 c_3_3)" --priority 0.9 --deadline 60 \\
        [--precondition "(map_loaded)"] [--context "(not (carrying robot1 p1))"]
    cbdi ctl desire remove robot1 visit          cbdi ctl desire check robot1 visit
    cbdi ctl belief add robot1 "(delivered p1)"   (also remove, check)
    cbdi ctl stop robot1 [robot2 ...] | --all      cbdi ctl resume robot1 | --all

`stop` is a safe stop: each agent cancels its search, lets the step running now end (a
durative action is not broken off midway), starts nothing more and keeps its intention
and desires, whose deadlines wait; the command returns once every executor is still
(within `--wait` seconds). It goes to the scheduler and to the executor, each on its own
endpoint: an executor stops even if its scheduler is dead or frozen, and tells the
agent's performers (`cbdi.performer`) to stop what they carry out. `resume` goes on at
both, and the scheduler plans the intention again from the beliefs of then.

Every other change goes through the agent's multi-agent request endpoint (its scheduler's
`rpc/request`), as another agent's would, under `--group` (default `operator`, which the
agent file must list in `allowed_groups`). Each `--precondition` or `--context` flag is
one clause, a list of literals that must all hold; any one clause that holds will do.

Exit codes: 0 accepted (for `check`: it holds), 1 refused with the reason (for `check`:
it does not hold), 2 bad usage, 3 no answer (no router, no such agent running). The
command line is read by `cbdi.ctl_args`.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import sys
from collections.abc import Sequence
from typing import Literal

import msgspec

from cbdi import keys
from cbdi.bus import Bus, BusConfig, open_bus, request
from cbdi.bus.zenoh_bus import DEFAULT_ENDPOINT
from cbdi.ctl_args import UsageError, build_request, parser, split_literals, validate
from cbdi.errors import CbdiError, ConfigError
from cbdi.security import CREDENTIALS_ENV, Credentials, discover, read_credentials
from cbdi.security.policy import OPERATOR
from cbdi.wire.agent import (
    AgentReply,
    AgentRequest,
    AgentState,
    ExecutorState,
    ExecutorStop,
    RequestOp,
    StateRequest,
)

__all__ = ["UsageError", "build_request", "format_state", "main", "split_literals"]

EXIT_OK, EXIT_REFUSED, EXIT_USAGE, EXIT_NO_ANSWER = 0, 1, 2, 3


def format_state(state: AgentState) -> str:
    """Render an agent's state for a terminal."""
    lines = [f"{state.agent} at t={state.time:g}"]
    cur = state.intention
    if cur is None:
        lines.append("intention: none")
    else:
        flags = "".join(
            f" [{f}]" for f, on in (("waiting", cur.waiting), ("stopping", cur.stopping)) if on
        )
        plan = f" (plan {cur.plan_id})" if cur.plan_id else " (no plan yet)"
        lines.append(f"intention: {cur.desire}{plan}{flags}")
        if cur.retry:
            lines.append(
                f"  {cur.retry}; searching again {cur.retry_when or 'when the beliefs change'}"
            )
        for s in cur.steps:
            status = s.status or "sent"
            lines.append(f"  {s.start:8.3f} [{s.duration:g}] {s.action}  {status}")
    lines.append(f"desires ({len(state.desires)}):")
    for d in state.desires:
        mark = "*" if cur is not None and cur.desire == d.name else " "
        deadline = "none" if d.deadline is None else f"{d.deadline:g}"
        lines.append(f" {mark} {d.name}  priority {d.priority:g}  deadline {deadline}")
        lines.append(f"      goal {' '.join(d.goal)}")
        for what, condition in (("precondition", d.precondition), ("context", d.context)):
            if condition:
                clauses = " or ".join("[" + " ".join(c) + "]" for c in condition)
                lines.append(f"      {what} {clauses}")
    if state.beliefs:
        lines.append(f"beliefs ({len(state.beliefs)}):")
        lines += [f"  {b}" for b in state.beliefs]
    return "\n".join(lines)


async def _show(bus: Bus, args: argparse.Namespace) -> int:
    key = keys.component_rpc(args.agent, "scheduler", "state")
    ask = StateRequest(beliefs=not args.no_beliefs)
    while True:
        state = await request(bus, key, ask, AgentState, timeout=args.timeout)
        if args.json:
            print(msgspec.json.encode(msgspec.to_builtins(state)).decode(), flush=True)
        else:
            clear = "\x1b[H\x1b[2J" if args.watch and sys.stdout.isatty() else ""
            print(clear + format_state(state) + ("\n" if args.watch else ""), flush=True)
        if not args.watch:
            return EXIT_OK
        await asyncio.sleep(args.watch)


async def _ask(bus: Bus, args: argparse.Namespace, req: AgentRequest) -> int:
    key = keys.agent_request(args.agent, args.group)
    reply = await request(bus, key, req, AgentReply, timeout=args.timeout)
    if not reply.accepted:
        print(f"refused: {reply.reason}", file=sys.stderr)
        return EXIT_REFUSED
    if args.op == "check":
        print("holds" if reply.holds else "does not hold")
        return EXIT_OK if reply.holds else EXIT_REFUSED
    print("accepted")
    return EXIT_OK


async def _agents(bus: Bus, seconds: float = 1.0) -> list[str]:
    """The agents whose schedulers are alive now (their liveliness tokens)."""
    found: set[str] = set()

    async def collect() -> None:
        async for event in bus.watch_alive(keys.alive(keys.service_id("scheduler", "*"))):
            if event.alive:
                found.add(keys.service_of_alive(event.key).split("/")[0])

    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(collect(), seconds)
    return sorted(found)


async def _stop(bus: Bus, args: argparse.Namespace) -> int:
    """Stop (or resume) each agent at its scheduler and at its executor.

    The scheduler keeps the intention and every desire and lets their deadlines wait;
    the executor starts nothing more, whatever the scheduler does (a dead or frozen
    scheduler cannot keep a robot moving), and tells its performers to stop theirs.
    """
    agents = args.agents or await _agents(bus)
    if not agents:
        print("cbdi ctl: no agent is running", file=sys.stderr)
        return EXIT_NO_ANSWER
    stopping = args.what == "stop"
    op: RequestOp = "halt" if stopping else "resume"
    req = AgentRequest(from_agent=args.sender, group=args.group, op=op)
    code = EXIT_OK
    minds: set[str] = set()  # the agents whose scheduler took the request
    for agent in agents:
        try:
            reply = await request(
                bus,
                keys.agent_request(agent, args.group),
                req,
                AgentReply,
                timeout=args.timeout,
            )
        except CbdiError as exc:
            print(f"{agent}: the scheduler did not answer ({exc})", file=sys.stderr)
        else:
            if reply.accepted:
                minds.add(agent)
            elif stopping or "not halted" not in reply.reason:
                print(f"{agent}: refused: {reply.reason}", file=sys.stderr)
                code = EXIT_REFUSED
        try:
            await _executor(bus, agent, args, "stop" if stopping else "resume")
        except CbdiError as exc:
            print(f"{agent}: the executor did not answer ({exc})", file=sys.stderr)
            code = code or EXIT_NO_ANSWER
    if not stopping or code:
        if not code:
            print("resumed " + " ".join(agents))
        return code
    try:
        async with asyncio.timeout(args.wait):
            for agent in agents:
                when = await _still(bus, agent, args, agent in minds)
                print(f"{agent} stopped at t={when:g}")
    except TimeoutError:
        print(f"cbdi ctl: not all still within {args.wait:g} s", file=sys.stderr)
        return EXIT_NO_ANSWER
    return EXIT_OK


async def _executor(
    bus: Bus, agent: str, args: argparse.Namespace, op: Literal["stop", "resume", "state"]
) -> ExecutorState:
    key = keys.component_rpc(agent, "executor", "stop")
    stop = ExecutorStop(from_agent=args.sender, op=op)
    return await request(bus, key, stop, ExecutorState, timeout=args.timeout)


async def _still(bus: Bus, agent: str, args: argparse.Namespace, mind: bool) -> float:
    """Wait until `agent`'s executor runs nothing (and its scheduler, if it took the
    stop, stopped arresting); return the simulated time."""
    while True:
        state = await _executor(bus, agent, args, "state")
        if not state.running and state.halted:
            if not mind:
                return state.time
            key = keys.component_rpc(agent, "scheduler", "state")
            try:
                seen = await request(
                    bus, key, StateRequest(beliefs=False), AgentState, timeout=args.timeout
                )
            except CbdiError:
                return state.time  # the scheduler went away since: the executor is still
            if seen.halted and not (seen.intention and seen.intention.stopping):
                return state.time
        await asyncio.sleep(0.1)


def _login(args: argparse.Namespace, connect: Sequence[str]) -> Credentials | None:
    """The operator's credentials: given, in the environment, or the local run's (none:
    a bus without security). A group they do not hold is refused here, with the reason
    (the router would drop the request unanswered)."""
    path = args.credentials or os.environ.get(CREDENTIALS_ENV) or discover(connect, OPERATOR)
    if not path:
        return None
    found = read_credentials(path)
    if args.what != "show" and args.group not in found.groups:  # show asks no group
        held = ", ".join(found.groups) or "none"
        raise UsageError(
            f"group {args.group!r} is not allowed for {found.identity!r} (its groups: {held};"
            f" credentials {path})"
        )
    return found


async def _run(args: argparse.Namespace, req: AgentRequest | None) -> int:
    connect = args.connect or os.environ.get("CBDI_CONNECT", DEFAULT_ENDPOINT).split(",")
    login = _login(args, connect)
    user, password = (login.user, login.password) if login else ("", "")
    cfg = BusConfig(
        connect=tuple(connect), connect_timeout=args.timeout, user=user, password=password
    )
    bus = await open_bus(cfg)
    try:
        if args.what in ("stop", "resume"):
            return await _stop(bus, args)
        return await (_show(bus, args) if req is None else _ask(bus, args, req))
    finally:
        await bus.close()


def main(argv: Sequence[str] | None = None) -> int:
    """Run `cbdi ctl`; return its exit code."""
    try:
        args = parser().parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0) and EXIT_USAGE
    try:
        validate(args)
        req = None if args.what in ("show", "stop", "resume") else build_request(args)
    except UsageError as exc:
        print(f"cbdi ctl: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        return asyncio.run(_run(args, req))
    except KeyboardInterrupt:
        return EXIT_OK
    except UsageError as exc:
        print(f"cbdi ctl: refused: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    except ConfigError as exc:
        print(f"cbdi ctl: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (CbdiError, TimeoutError) as exc:
        who = getattr(args, "agent", None) or "an agent"
        print(
            f"cbdi ctl: no answer from {who}'s scheduler: {exc or 'timed out'}"
            " (is the agent running, and --connect its router?)",
            file=sys.stderr,
        )
        return EXIT_NO_ANSWER


if __name__ == "__main__":
    sys.exit(main())
