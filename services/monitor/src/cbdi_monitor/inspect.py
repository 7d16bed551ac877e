"""`cbdi inspect run.mcap`: what is in a recording, and what each agent did.

Channels with message counts, the duration, and per agent: the domain's own counters
(what its package registers under its simulator's name, entry point `cbdi.counters`:
successes of an action by a counter's name, e.g. a grid robot's moves), actions by name
and outcome, failed and rejected actions, the simulated time of its first action,
partial plans passed to the executor (`plans`), early arrests, goals achieved and
desires dropped; and from its planner's messages (counted by `cbdi.tally`, as `cbdi
up` counts them live): plans published, replans (by purpose), forecast-triggered repairs,
improvements, search rounds and the nodes they expanded, forecasts by kind. The planner
counts are `null` for an agent whose planner said nothing (a scripted robot).
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from cbdi import keys
from cbdi.errors import CbdiError, WireError
from cbdi.plugins import domain_counters
from cbdi.tally import MESSAGES, SCHEMAS, PlannerTally
from cbdi.wire.agent import ArrestReport, DesireEvent, PartialPlan
from cbdi.wire.base import decode, decode_any
from cbdi.wire.common import RunFinished
from cbdi.wire.world import ActionOutcome, ActionRequest, Tick, WorldInfo, WorldStats
from cbdi_monitor.reader import RecordedMessage, read_messages

__all__ = ["AgentReport", "Inspection", "inspect_messages", "main"]

ACT_REQUEST = keys.trace_request(keys.world_rpc("act"))


@dataclass
class AgentReport:
    """What one agent did in a recording."""

    counters: dict[str, int] = field(default_factory=dict)  # the domain's, by name
    actions: dict[str, int] = field(default_factory=dict)
    failed: int = 0
    rejected: int = 0
    requests: int = 0
    first_action_time: float | None = None
    plans: int = 0
    arrests: int = 0
    goals_achieved: int = 0
    desires_dropped: int = 0
    plans_published: int | None = None
    replans: int | None = None
    replans_by: dict[str, int] | None = None
    forecast_repairs: int | None = None
    improvements: int | None = None
    search_rounds: int | None = None
    search_expanded: int | None = None
    forecasts: dict[str, int] | None = None


@dataclass
class Inspection:
    """The whole report of `cbdi inspect`."""

    messages: int = 0
    channels: dict[str, int] = field(default_factory=dict)
    duration_s: float = 0.0
    sim_time: float = 0.0
    epochs: int = 0
    result: str = ""
    simulator: str = ""  # the world's (`WorldInfo.simulator`): whose counters to count
    undecodable: int = 0
    agents: dict[str, AgentReport] = field(default_factory=dict)
    world_stats: dict[str, dict[str, int]] = field(default_factory=dict)


def inspect_messages(messages: Iterable[RecordedMessage]) -> Inspection:
    """Summarise recorded messages (pure: no files, no bus)."""
    report = Inspection()
    tally = PlannerTally()
    counts: Counter[str] = Counter()
    first_ns = last_ns = 0
    now = 0.0
    for m in messages:
        counts[m.key] += 1
        first_ns = first_ns or m.log_ns
        last_ns = max(last_ns, m.log_ns)
        try:
            if m.schema in SCHEMAS:
                tally.observe(m.key, decode_any(m.payload, MESSAGES, m.key))
            now = _account(report, m, now)
        except WireError:
            report.undecodable += 1
    for name in tally.agents:
        _planner(_agent(report, name), tally, name)
    _count(report, domain_counters(report.simulator) if report.simulator else {})
    report.messages = sum(counts.values())
    report.channels = dict(sorted(counts.items()))
    report.duration_s = round((last_ns - first_ns) / 1e9, 3)
    return report


def _agent(report: Inspection, name: str) -> AgentReport:
    return report.agents.setdefault(name, AgentReport())


def _account(report: Inspection, m: RecordedMessage, now: float) -> float:
    """Fold one message into the report; return the simulated time now."""
    if m.schema == "cbdi.world.Tick/1":
        tick = decode(m.payload, Tick, m.key)
        report.epochs, report.sim_time = tick.epoch, tick.time
        return tick.time
    if m.schema == "cbdi.world.ActionOutcome/1":
        _outcome(_agent(report, (o := decode(m.payload, ActionOutcome, m.key)).agent), o)
    elif m.schema == "cbdi.world.ActionRequest/1" and _action_request(m.key):
        agent = _agent(report, decode(m.payload, ActionRequest, m.key).agent)
        agent.requests += 1
        if agent.first_action_time is None:
            agent.first_action_time = now
    elif m.schema == "cbdi.world.WorldStats/1":
        stats = decode(m.payload, WorldStats, m.key)
        report.world_stats = {a.agent: _stats_dict(a) for a in stats.agents}
    elif m.schema == "cbdi.world.WorldInfo/1":
        report.simulator = decode(m.payload, WorldInfo, m.key).simulator
    elif m.schema == "cbdi.RunFinished/1":
        report.result = decode(m.payload, RunFinished, m.key).reason
    else:
        _agent_message(report, m)
    return now


def _action_request(key: str) -> bool:
    """Whether `key` mirrors an action request: to the world, or to a performer."""
    asked = keys.traced_request(key)
    return key == ACT_REQUEST or keys.is_request_to(asked, "performer")


def _agent_message(report: Inspection, m: RecordedMessage) -> None:
    """Count what the agents' own services said (plans, arrests, desires)."""
    if m.schema == "cbdi.agent.PartialPlan/1" and keys.is_stream(m.key, "scheduler", "plans"):
        _agent(report, decode(m.payload, PartialPlan, m.key).agent).plans += 1
    elif m.schema == "cbdi.agent.ArrestReport/1":
        _agent(report, decode(m.payload, ArrestReport, m.key).agent).arrests += 1
    elif m.schema == "cbdi.agent.DesireEvent/1":
        event = decode(m.payload, DesireEvent, m.key)
        if event.event == "achieved":
            _agent(report, event.agent).goals_achieved += 1
        elif event.event == "dropped":
            _agent(report, event.agent).desires_dropped += 1


def _planner(agent: AgentReport, tally: PlannerTally, name: str) -> None:
    c = tally.counts(name)
    agent.plans_published, agent.replans, agent.replans_by = c.plans, c.replans, c.replans_by
    agent.forecast_repairs, agent.improvements = c.forecast_repairs, c.improvements
    agent.search_rounds, agent.search_expanded = c.search_rounds, c.expanded
    agent.forecasts = c.forecasts


def _outcome(agent: AgentReport, o: ActionOutcome) -> None:
    key = f"{o.action}:{o.status}"
    agent.actions[key] = agent.actions.get(key, 0) + 1
    if o.status != "succeeded":
        agent.failed += 1


def _count(report: Inspection, counters: dict[str, str]) -> None:
    """Fill each agent's domain counters: the successes of the action each one counts."""
    for agent in report.agents.values():
        agent.counters = {c: agent.actions.get(f"{a}:succeeded", 0) for c, a in counters.items()}


def _stats_dict(a: Any) -> dict[str, int]:
    """One agent's world counters: the simulator's own, then the generic ones."""
    return {**a.counts, "failed": a.failed, "rejected": a.rejected}


def render(report: Inspection) -> str:
    """Format a report for people."""
    lines = [
        f"{report.messages} messages on {len(report.channels)} channels, "
        f"{report.duration_s:.1f} s recorded, {report.epochs} epochs, "
        f"{report.sim_time:.1f} simulated s, result: {report.result or '(no end seen)'}"
    ]
    lines += [f"  {count:8d}  {key}" for key, count in report.channels.items()]
    for name, a in sorted(report.agents.items()):
        first = "-" if a.first_action_time is None else f"t={a.first_action_time:g}"
        own = (
            "".join(f"{k}={v} " for k, v in a.counters.items()) if any(a.counters.values()) else ""
        )
        lines.append(
            f"agent {name}: {own}failed={a.failed} requests={a.requests} first action at {first}"
        )
        lines.append("    " + " ".join(f"{k}={v}" for k, v in sorted(a.actions.items())))
        if a.replans is not None:
            lines.append("    " + _render_planner(a))
    return "\n".join(lines)


def _render_planner(a: AgentReport) -> str:
    by = " ".join(f"{k}={v}" for k, v in (a.replans_by or {}).items() if v)
    seen = " ".join(f"{k}={v}" for k, v in (a.forecasts or {}).items())
    return (
        f"planner: plans={a.plans_published} replans={a.replans}"
        + (f" ({by})" if by else "")
        + f" forecast_repairs={a.forecast_repairs} improvements={a.improvements}"
        f" search_rounds={a.search_rounds} expanded={a.search_expanded} forecasts: {seen}"
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Run `cbdi inspect FILE [--json]`."""
    import argparse

    parser = argparse.ArgumentParser(prog="cbdi inspect", description=__doc__)
    parser.add_argument("file", help="an MCAP recording")
    parser.add_argument("--json", action="store_true", help="machine-readable output")
    args = parser.parse_args(list(argv) if argv is not None else None)
    try:
        report = inspect_messages(read_messages(args.file))
    except CbdiError as exc:
        print(f"cbdi inspect: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(asdict(report), indent=2) if args.json else render(report))
    return 0
