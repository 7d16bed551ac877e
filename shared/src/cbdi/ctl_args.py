"""The command line of `cbdi ctl`: its parser, the checks of what it was given, and the
request a `desire` or `belief` command makes (`cbdi.ctl` sends it).
"""

from __future__ import annotations

import argparse

from cbdi import keys
from cbdi.bus.zenoh_bus import DEFAULT_ENDPOINT
from cbdi.wire.agent import AgentRequest

__all__ = ["UsageError", "build_request", "parser", "split_literals", "validate"]


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


def parser() -> argparse.ArgumentParser:
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


def validate(args: argparse.Namespace) -> None:
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
