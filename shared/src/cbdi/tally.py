"""Count what each agent's planner did: plans, replans, forecast repairs, search rounds.

Pure (no bus, no clock, no files): feed `PlannerTally.observe(key, message)` the messages
published on `KEYS`, in arrival order. `cbdi up` counts live with it, `cbdi inspect` and
the rerun view count from a recording, so both report the same numbers.

Definitions, per agent:

- A *plan* is one plan id as the executor sees it (a line, in the planner's words). Its
  first `PartialPlan` on `cbdi/<a>/planner/plans` has a baseline other than its own plan
  id (empty for a fresh search, the last committed step for a repair, a revised goal or
  an improvement); the partial plans that continue it (baseline = its plan id) add steps
  to it and are not counted again.
- An *intention* is the span of search requests for one desire: it begins with a `start`
  request for another desire than the current one, or with the first request after a
  `cancel` (the desire achieved, dropped or preempted). A `start` for the same desire (a
  step failed or was refused, a failed search is retried) or a `revise` stays in it.
  A plan belongs to the intention of the request it answers (`PartialPlan.request_id`),
  whenever each of them arrives: the requests come from the scheduler and the plans
  from the planner, and the bus keeps no order between two senders. A plan that names
  no request (a recording made before plans did) belongs to the intention open when it
  arrived.
- `replans`: plans published after the first plan of their intention. Online: repairs,
  revised goals, improvements and fresh searches after a failed step; offline: every plan
  after the first. `replans_by` splits them by purpose: the plan's own
  (`PartialPlan.purpose`), else its search rounds' (`new`, `repair`, `revise`,
  `improve`), else (an offline plan of an old recording) `revise` after a revise
  request, `new` otherwise.
- `forecast_repairs`: repair plans published, that is `fails_after_committed` forecasts
  that led to a repair plan. Each repair search starts from one such forecast; a repair
  search that fails or is outdated publishes no plan and is not counted (the forecast
  still is, in `forecasts`).
- `improvements`: improved plans published (purpose `improve`); also in `replans`.
- `forecasts`: forecast reports by kind (FORECAST_KINDS). The planner reports a forecast
  only when it differs from its last one, so these count changes of outlook.
- `search_rounds`, `expanded`, `search_seconds`: rounds reported, the nodes they
  expanded and the seconds they took (`rounds_by`: rounds by purpose).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from cbdi import keys
from cbdi.wire.agent import PartialPlan
from cbdi.wire.base import Message, schema_of
from cbdi.wire.planner import FORECAST_KINDS, ForecastReport, SearchRequest, SearchRound

__all__ = [
    "KEYS",
    "MESSAGES",
    "PURPOSES",
    "SCHEMAS",
    "PlanLine",
    "PlannerCounts",
    "PlannerTally",
]

PURPOSES = ("new", "repair", "revise", "improve")
# What to subscribe to (or read from a recording), and the message classes found there.
KEYS = (
    keys.planner_requests("*"),
    keys.planner_plans("*"),
    keys.planner_rounds("*"),
    keys.planner_forecasts("*"),
)
MESSAGES: tuple[type[Message], ...] = (SearchRequest, PartialPlan, SearchRound, ForecastReport)
SCHEMAS = frozenset(schema_of(cls) for cls in MESSAGES)
_KEY_OF = {
    SearchRequest: keys.planner_requests,
    PartialPlan: keys.planner_plans,
    SearchRound: keys.planner_rounds,
    ForecastReport: keys.planner_forecasts,
}


def _zeros(names: tuple[str, ...]) -> dict[str, int]:
    return dict.fromkeys(names, 0)


@dataclass
class PlanLine:
    """One plan id: the intention it serves, whether it is a replan, its steps so far."""

    agent: str
    plan_id: str
    intention: int
    replan: bool
    purpose: str  # from its rounds; "" until one names it
    fallback: str  # the purpose when no round names one (offline)
    applies_after: str
    steps: int = 0
    complete: bool = False
    request_id: str = ""  # the request it answers ("": not said)

    @property
    def kind(self) -> str:
        """Return the plan's purpose: `new`, `repair`, `revise` or `improve`."""
        return self.purpose or self.fallback


@dataclass
class PlannerCounts:
    """One agent's (or every agent's) planner counts; see the module for definitions."""

    plans: int = 0
    replans: int = 0
    forecast_repairs: int = 0
    improvements: int = 0
    search_rounds: int = 0
    expanded: int = 0
    search_seconds: float = 0.0
    replans_by: dict[str, int] = field(default_factory=lambda: _zeros(PURPOSES))
    rounds_by: dict[str, int] = field(default_factory=lambda: _zeros(PURPOSES))
    forecasts: dict[str, int] = field(default_factory=lambda: _zeros(FORECAST_KINDS))

    def add(self, other: PlannerCounts) -> None:
        """Add `other`'s counts to these (for totals)."""
        for name in ("plans", "replans", "forecast_repairs", "improvements", "search_rounds"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        self.expanded += other.expanded
        self.search_seconds = round(self.search_seconds + other.search_seconds, 6)
        for mine, theirs in (
            (self.replans_by, other.replans_by),
            (self.rounds_by, other.rounds_by),
            (self.forecasts, other.forecasts),
        ):
            for k, v in theirs.items():
                mine[k] = mine.get(k, 0) + v

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class _Agent:
    """What the tally keeps of one agent."""

    intention: int = 0
    desire: str | None = None  # None: no intention open
    last_request: str = ""
    intention_of: dict[str, int] = field(default_factory=dict)  # request id -> intention
    lines: dict[str, PlanLine] = field(default_factory=dict)  # by plan id, latest wins
    order: list[PlanLine] = field(default_factory=list)
    purposes: dict[str, str] = field(default_factory=dict)  # plan id -> purpose of its rounds
    rounds: PlannerCounts = field(default_factory=PlannerCounts)  # rounds, forecasts only


class PlannerTally:
    """Fold planner messages into per-agent counts."""

    def __init__(self, agents: tuple[str, ...] | list[str] = ()) -> None:
        self._agents: dict[str, _Agent] = {a: _Agent() for a in agents}

    @property
    def agents(self) -> list[str]:
        return sorted(self._agents)

    def observe(self, key: str, msg: Message) -> PlanLine | None:
        """Count one message received on `key`; return the plan it started, if any.

        Messages on other keys than their own (`PartialPlan`s the scheduler passes on to
        its executor, for one) are ignored.
        """
        key_of = _KEY_OF.get(type(msg))
        agent = getattr(msg, "agent", "")
        if key_of is None or not agent or key != key_of(agent):
            return None
        state = self._agents.setdefault(agent, _Agent())
        if isinstance(msg, SearchRequest):
            self._request(state, msg)
        elif isinstance(msg, PartialPlan):
            return self._plan(state, msg)
        elif isinstance(msg, SearchRound):
            self._round(state, msg)
        elif isinstance(msg, ForecastReport):
            forecasts = state.rounds.forecasts
            forecasts[msg.kind] = forecasts.get(msg.kind, 0) + 1
        return None

    def line(self, agent: str, plan_id: str) -> PlanLine | None:
        """Return the latest plan of `agent` with `plan_id`, if it was published."""
        state = self._agents.get(agent)
        return state.lines.get(plan_id) if state else None

    def counts(self, agent: str) -> PlannerCounts:
        """Return `agent`'s counts (zeros for an agent never heard of)."""
        state = self._agents.get(agent) or _Agent()
        self._classify(state)
        out = PlannerCounts()
        out.add(state.rounds)
        out.plans = len(state.order)
        for line in state.order:
            kind = line.kind
            if kind == "repair":
                out.forecast_repairs += 1
            elif kind == "improve":
                out.improvements += 1
            if line.replan:
                out.replans += 1
                out.replans_by[kind] = out.replans_by.get(kind, 0) + 1
        return out

    def total(self) -> PlannerCounts:
        """Return the counts of every agent together."""
        out = PlannerCounts()
        for agent in self._agents:
            out.add(self.counts(agent))
        return out

    def summary(self) -> dict[str, Any]:
        """Return `{"agents": {name: counts}, "total": counts}` as plain dicts."""
        return {
            "agents": {a: self.counts(a).as_dict() for a in self.agents},
            "total": self.total().as_dict(),
        }

    # -- folding --------------------------------------------------------------------------
    @staticmethod
    def _request(state: _Agent, req: SearchRequest) -> None:
        if req.kind == "cancel":
            state.desire = None
            return
        if state.desire is None or (req.kind == "start" and req.desire != state.desire):
            state.intention += 1
        state.desire, state.last_request = req.desire, req.kind
        if req.kind == "start" or req.request_id not in state.intention_of:
            state.intention_of[req.request_id] = state.intention  # a revise keeps its id's

    @staticmethod
    def _plan(state: _Agent, plan: PartialPlan) -> PlanLine | None:
        if plan.baseline == plan.plan_id:  # more steps of a published plan
            line = state.lines.get(plan.plan_id)
            if line is not None:
                line.steps += len(plan.steps)
                line.complete = plan.complete
            return None
        line = PlanLine(
            agent=plan.agent,
            plan_id=plan.plan_id,
            intention=state.intention,
            replan=False,
            purpose=plan.purpose or state.purposes.get(plan.plan_id, ""),
            fallback="revise" if state.last_request == "revise" else "new",
            applies_after=plan.applies_after,
            steps=len(plan.steps),
            complete=plan.complete,
            request_id=plan.request_id,
        )
        state.lines[plan.plan_id] = line
        state.order.append(line)
        PlannerTally._classify(state)
        return line

    @staticmethod
    def _classify(state: _Agent) -> None:
        """Put each plan in its request's intention (if both are known) and mark the
        plans after the first of an intention as replans, in the planner's order."""
        planned: set[int] = set()
        for line in state.order:
            line.intention = state.intention_of.get(line.request_id, line.intention)
            line.replan = line.intention in planned
            planned.add(line.intention)

    @staticmethod
    def _round(state: _Agent, r: SearchRound) -> None:
        state.purposes[r.plan_id] = r.purpose
        line = state.lines.get(r.plan_id)
        if line is not None and not line.purpose:  # its rounds came after it
            line.purpose = r.purpose
        counts = state.rounds
        counts.search_rounds += 1
        counts.expanded += r.expanded
        counts.search_seconds = round(counts.search_seconds + r.seconds, 6)
        counts.rounds_by[r.purpose] = counts.rounds_by.get(r.purpose, 0) + 1
