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
it does not hold), 2 bad usage, 3 no answer (no router, no such agent running).
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

__all__ = ["format_state", "main", "split_literals"]

EXIT_OK, EXIT_REFUSED, EXIT_USAGE, EXIT_NO_ANSWER = 0, 1, 2, 3


class UsageError(ValueError):
    """A command line that does not read; the message says what is wrong."""


def split_literals(text: str) -> list[str]:
    """Split `(a b) (not (c d))` into its top-level literals."""
    out, depth, start = [], 0, -1
    for i, ch in enumerate(text):
        if ch == "(":
            if depth == 0:
                start = i
            depth += 1
        elif ch == ")":
            depth -= 1
            if depth < 0:
                raise UsageError(f"{text!r}: ')' at {i + 1} closes nothing")
            if depth == 0:
                out.append(text[start : i + 1])
        elif depth == 0 and not ch.isspace():
            raise UsageError(f"{text!r}: expected literals like (in robot1 c_1_1), got {ch!r}")
    if depth:
        raise UsageError(f"{text!r}: missing ')'")
    if not out:
        raise UsageError("expected at least one literal, like (in robot1 c_1_1)")
    return out


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


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cbdi ctl",
        description="See and change a running agent's beliefs, desires and intentions.",
        epilog="Exit: 0 accepted (check: holds), 1 refused (check: does not hold), "
        "2 bad usage, 3 no answer.",
    )
    _common(p, argparse.ArgumentParser(add_help=False))
    sub = p.add_subparsers(dest="what", required=True)
    common = argparse.ArgumentParser(add_help=False)
    _common(common, None)

    def leaf(parent: argparse._SubParsersAction, name: str, text: str) -> argparse.ArgumentParser:  # type: ignore[type-arg]
        return parent.add_parser(name, help=text, parents=[common])  # type: ignore[no-any-return]

    show = leaf(sub, "show", "an agent's beliefs, desires, intention and plan")
    show.add_argument("agent")
    show.add_argument("--watch", type=float, default=0.0, metavar="SECONDS", help="repeat")
    show.add_argument("--no-beliefs", action="store_true", help="leave the beliefs out")
    show.add_argument("--json", action="store_true", help="JSON, one object per line")

    desire = sub.add_parser("desire", help="add, remove or check a desire")
    dsub = desire.add_subparsers(dest="op", required=True)
    add = leaf(dsub, "add", "add a desire")
    add.add_argument("agent")
    add.add_argument("name")
    add.add_argument("goal", nargs="+", help="goal literals, e.g. '(in robot1 c_3_3)'")
    add.add_argument("--priority", type=float, default=0.5, help="0 to 1 (default 0.5)")
    add.add_argument("--deadline", type=float, default=0.0, help="seconds from now (0: none)")
    add.add_argument("--precondition", action="append", default=[], metavar="CLAUSE")
    add.add_argument("--context", action="append", default=[], metavar="CLAUSE")
    for op in ("remove", "check"):
        one = leaf(dsub, op, f"{op} a desire")
        one.add_argument("agent")
        one.add_argument("name")

    belief = sub.add_parser("belief", help="add, remove or check a belief, or tell an event")
    bsub = belief.add_subparsers(dest="op", required=True)
    for op, text in (
        ("add", "add a belief ('(= (battery robot1) 40)' sets a value)"),
        ("remove", "remove a belief"),
        ("check", "check a belief"),
        ("event", "tell an event: the rules of the next cycle see it once, never believed"),
    ):
        one = leaf(bsub, op, text)
        one.add_argument("agent")
        one.add_argument("belief", help="e.g. '(delivered p1)'")
    for op, text in (("stop", "stop agents safely"), ("resume", "resume stopped agents")):
        one = leaf(sub, op, text)
        one.add_argument("agents", nargs="*", metavar="AGENT")
        one.add_argument("--all", action="store_true", help="every agent running now")
        one.add_argument(
            "--wait", type=float, default=30.0, help="stop: seconds to wait for stillness"
        )
    return p


def _common(p: argparse.ArgumentParser, top: object) -> None:
    """The options every subcommand takes, before or after it (`top`: the top level,
    which holds the defaults; after the subcommand a flag given overrides them)."""
    default = (lambda v: v) if top is not None else (lambda v: argparse.SUPPRESS)
    p.add_argument(
        "--connect",
        action="append",
        default=default(None),
        help=f"Zenoh endpoint (repeatable; default $CBDI_CONNECT or {DEFAULT_ENDPOINT})",
    )
    p.add_argument(
        "--credentials",
        default=default(None),
        help="file with the operator's Zenoh user and password (default $CBDI_CREDENTIALS, "
        "or the operator's of the local `cbdi up` run on --connect's port)",
    )
    p.add_argument("--group", default=default("operator"), help="the group asked under")
    p.add_argument("--from", dest="sender", default=default("operator"), help="who asks")
    p.add_argument(
        "--timeout", type=float, default=default(5.0), help="seconds to wait for an answer"
    )


_OPS = {
    ("desire", "add"): "add_desire",
    ("desire", "remove"): "del_desire",
    ("desire", "check"): "check_desire",
    ("belief", "add"): "add_belief",
    ("belief", "remove"): "del_belief",
    ("belief", "check"): "check_belief",
    ("belief", "event"): "event",
}


def build_request(args: argparse.Namespace) -> AgentRequest:
    """Turn parsed `desire`/`belief` arguments into the request (UsageError if bad)."""
    op = _OPS[(args.what, args.op)]
    fields: dict[str, object] = {}
    if args.what == "belief":
        fields["belief"] = args.belief
    else:
        fields["desire"] = args.name
    if op == "add_desire":
        if not 0.0 <= args.priority <= 1.0:
            raise UsageError(f"--priority must be between 0 and 1, got {args.priority:g}")
        if not 0.0 <= args.deadline < float("inf"):
            raise UsageError(f"--deadline must be a finite number >= 0, got {args.deadline:g}")
        fields |= {
            "goal": [lit for g in args.goal for lit in split_literals(g)],
            "priority": args.priority,
            "deadline": args.deadline,
            "precondition": [split_literals(c) for c in args.precondition],
            "context": [split_literals(c) for c in args.context],
        }
    try:
        return AgentRequest(from_agent=args.sender, group=args.group, op=op, **fields)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise UsageError(str(exc)) from None


def _validate(args: argparse.Namespace) -> None:
    if args.what in ("stop", "resume"):
        if bool(args.agents) == args.all:
            raise UsageError(f"{args.what}: name the agents, or give --all")
        if not (0 < args.wait < float("inf")):
            raise UsageError(f"--wait must be a number of seconds above 0, got {args.wait:g}")
    names = [("agent", n) for n in getattr(args, "agents", None) or [getattr(args, "agent", "")]]
    for what, name in [*([] if getattr(args, "all", False) else names), ("sender", args.sender)]:
        try:
            keys.validate_name(name, what)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    if not args.group:
        raise UsageError("--group must not be empty")
    try:
        keys.validate_name(args.group, "group")  # a chunk of the key asked on
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if not (0 < args.timeout < float("inf")):
        raise UsageError(f"--timeout must be a number of seconds above 0, got {args.timeout:g}")


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
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0) and EXIT_USAGE
    try:
        _validate(args)
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
