"""Where two runs part: their executed actions, leg by leg, side by side.

A run's actions (what each agent asked the world to do, with the outcome's time) fall
into *legs*: the travel actions (`--travel`, default `move`) up to the next other action
(a pickup, a recycle, a job done). For one recording it prints each agent's legs: the
action that ends the leg, the moves it took, when it ended and how long the agent stood
idle in it, and the steps the executor refused or that failed, with the reason. For two
recordings of the same situation (online and offline, or before and after a change) it
prints them side by side, the moves and time each run spent per leg, and the first leg
where they part: a different job taken next, or the same job reached by a longer way.

    .venv/bin/python benchmarks/legs.py online.mcap [offline.mcap] [--agent robot1]
        [--travel move]

Record runs with `cbdi up ... --record FILE` (benchmarks/fleet.py and table1.py keep
theirs with `--keep`, where they have it).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from itertools import zip_longest

from cbdi.wire import decode_any
from cbdi.wire.agent import ActionStatus
from cbdi.wire.world import ActionOutcome, ActionRequest
from cbdi_monitor.reader import read_messages


@dataclass
class Leg:
    """Travel actions up to one other action (`end`; "" for the travel after the last)."""

    end: str = ""
    moves: int = 0
    started: float = 0.0
    ended: float = 0.0
    busy: float = 0.0

    @property
    def idle(self) -> float:
        return max(0.0, self.ended - self.started - self.busy)


@dataclass
class Run:
    """One agent's legs in one recording, and its executor's refusals and failures."""

    path: str
    agent: str
    legs: list[Leg] = field(default_factory=list)
    trouble: list[str] = field(default_factory=list)

    @property
    def moves(self) -> int:
        return sum(leg.moves for leg in self.legs)

    @property
    def time(self) -> float:
        return self.legs[-1].ended if self.legs else 0.0


def read_run(path: str, agent: str, travel: frozenset[str]) -> Run:
    """Read `agent`'s executed actions from the recording `path` into legs."""
    keys = [
        "cbdi/trace/world/rpc/act/request",
        f"cbdi/world/outcomes/{agent}",
        f"cbdi/{agent}/executor/status",
    ]
    asked: dict[str, ActionRequest] = {}
    run = Run(path, agent)
    leg = Leg()
    classes = (ActionRequest, ActionOutcome, ActionStatus)
    for m in read_messages(path, keys):
        msg = decode_any(m.payload, classes, m.key)
        if isinstance(msg, ActionRequest) and msg.agent == agent:
            asked[msg.request_id] = msg
        elif isinstance(msg, ActionOutcome) and msg.request_id in asked:
            req = asked.pop(msg.request_id)
            if msg.status != "succeeded":
                run.trouble.append(f"t={msg.time:g} {req.action} {msg.status}: {msg.reason}")
                continue
            leg.ended = msg.time
            leg.busy += req.duration
            if req.action in travel:
                leg.moves += 1
                continue
            leg.end = " ".join([req.action, *req.args])
            run.legs.append(leg)
            leg = Leg(started=msg.time, ended=msg.time)
        elif isinstance(msg, ActionStatus) and msg.status in ("refused", "failed"):
            run.trouble.append(f"t={msg.time:g} {msg.action} {msg.status}: {msg.reason}")
    if leg.moves:
        run.legs.append(leg)
    return run


def describe(run: Run) -> Iterator[str]:
    yield f"{run.path} {run.agent}: {run.moves} moves, {len(run.legs)} legs, t={run.time:g}"
    for k, leg in enumerate(run.legs, 1):
        yield (
            f"  {k:>3} {leg.moves:>4} moves  t={leg.ended:>7.1f}  idle {leg.idle:>5.1f}  "
            f"{leg.end or '(travel)'}"
        )
    for line in run.trouble:
        yield f"  ! {line}"


def compare(a: Run, b: Run) -> Iterator[str]:
    """The two runs side by side, and the first leg where they part."""
    yield f"A {a.path}: {a.moves} moves, t={a.time:g}, {len(a.trouble)} refused or failed"
    yield f"B {b.path}: {b.moves} moves, t={b.time:g}, {len(b.trouble)} refused or failed"
    yield f"{'leg':>4} {'A moves':>8} {'A t':>7} {'B moves':>8} {'B t':>7}  A ends / B ends"
    parted = None
    for k, (x, y) in enumerate(zip_longest(a.legs, b.legs), 1):
        xa = (x.moves, x.ended, x.end) if x else (0, 0.0, "-")
        yb = (y.moves, y.ended, y.end) if y else (0, 0.0, "-")
        same = xa[2] == yb[2]
        if parted is None and (not same or xa[0] != yb[0]):
            parted = (k, same, xa, yb)
        ends = xa[2] if same else f"{xa[2]} / {yb[2]}"
        yield f"{k:>4} {xa[0]:>8} {xa[1]:>7.1f} {yb[0]:>8} {yb[1]:>7.1f}  {ends}"
    yield from costliest(a, b)
    if parted is None:
        yield "the runs do the same jobs in the same order with the same moves"
        return
    k, same, xa, yb = parted
    if same:
        yield f"they part at leg {k}: the same job ({xa[2]}), A in {xa[0]} moves, B in {yb[0]}"
    else:
        yield f"they part at leg {k}: A takes up {xa[2]}, B {yb[2]}"


def costliest(a: Run, b: Run, most: int = 3) -> Iterator[str]:
    """The jobs both runs did whose legs differ most in moves, each way."""
    moves_a = {leg.end: leg.moves for leg in a.legs if leg.end}
    moves_b = {leg.end: leg.moves for leg in b.legs if leg.end}
    both = sorted(set(moves_a) & set(moves_b), key=lambda e: moves_a[e] - moves_b[e])
    for name, jobs in (("A", both[::-1][:most]), ("B", both[:most])):
        worse = [
            (e, moves_a[e], moves_b[e])
            for e in jobs
            if (moves_a[e] > moves_b[e]) == (name == "A") and moves_a[e] != moves_b[e]
        ]
        for e, ma, mb in worse:
            yield f"{name} went the longer way to {e}: {ma} moves against {mb}"


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("recordings", nargs="+", help="one or two MCAP recordings")
    p.add_argument("--agent", default="robot1")
    p.add_argument("--travel", default="move", help="travel actions, comma-separated")
    args = p.parse_args(argv)
    if len(args.recordings) > 2:
        p.error("one or two recordings")
    travel = frozenset(t.strip() for t in args.travel.split(",") if t.strip())
    runs = [read_run(path, args.agent, travel) for path in args.recordings]
    if any(not r.legs for r in runs):
        empty = next(r.path for r in runs if not r.legs)
        print(f"{empty}: no action of {args.agent} recorded", file=sys.stderr)
        return 1
    lines = describe(runs[0]) if len(runs) == 1 else compare(runs[0], runs[1])
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
