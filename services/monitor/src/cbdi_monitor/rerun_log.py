"""Turn cbdi messages into rerun entities: the map, bodies, intents, logs and plots.

Entity layout (what a user sees in the viewer):

- `world/map/floor` and `world/map/<layer>` (static boxes: the layers of the map's
  `WorldInfo.view`, e.g. walls and bins), `world/graph/links` and `world/graph/places` (a
  graph's links, lines, and places, labelled points), `world/people`, `world/items`
- `world/robots` (points labelled with names), `agents/<name>/intent` (the requested move)
- `agents/<name>/log` (text log: requests, outcomes, desires, search requests, plans and
  replans with their purpose, failure forecasts, search fall-backs, step statuses, early
  arrests), `health` (services up/down)
- `world/plans/<name>/committed` and `world/plans/<name>/rest`: the cells the current
  plan's moves still visit, from the robot; the committed part (steps running or done,
  up to the last committed step of the latest forecast, and what a replacing plan takes
  over from the old one up to its `applies_after`) thick, the rest, which a repair may
  still change, thin and pale
- `plots/<name>/<counter>` (the world's statistics: moves, failed, blocked and the
  simulator's own counters by name)
- `plots/<name>/planner/{expanded,best_h,round_seconds,search_rounds}` per search round,
  `plots/<name>/planner/{replans,forecast_repairs,plan_steps}` per published plan,
  `plots/<name>/forecasts/<kind>` (forecasts so far, per kind; counted by `cbdi.tally`)

Timelines: `epoch` (sequence) and `sim_time` (simulated seconds).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from cbdi import keys
from cbdi.errors import WireError
from cbdi.tally import PlannerTally
from cbdi.wire.agent import ActionStatus, ArrestReport, DesireEvent, PartialPlan, PlanStep
from cbdi.wire.base import decode
from cbdi.wire.common import Liveliness, RunFinished
from cbdi.wire.planner import FORECAST_KINDS, ForecastReport, SearchRequest, SearchRound
from cbdi.wire.world import (
    ActionOutcome,
    ActionRequest,
    MapView,
    Tick,
    WorldInfo,
    WorldSnapshot,
    WorldStats,
)
from cbdi_monitor.reader import RecordedMessage

__all__ = ["RerunLogger"]

ROBOT_COLOURS = [
    (230, 80, 60),
    (60, 120, 230),
    (60, 180, 90),
    (200, 140, 30),
    (150, 80, 200),
    (30, 170, 170),
    (220, 90, 160),
    (120, 120, 120),
]
ENDED = ("succeeded", "failed", "refused", "cancelled")


@dataclass
class Route:
    """The plan an agent follows, as far as the map shows it: its steps in order (a
    replacing plan's own after the old plan's steps it takes over), those that ended, and
    the index of the last committed one (-1: none)."""

    plan_id: str = ""
    steps: list[PlanStep] = field(default_factory=list)
    ended: set[str] = field(default_factory=set)
    committed: int = -1
    retired: set[str] = field(default_factory=set)

    def take(self, plan: PartialPlan) -> bool:
        """Add `plan`'s steps: more of this plan, or a plan replacing it; False: stale."""
        if plan.plan_id in self.retired:
            return False  # passed on late, after the plan that replaced it
        if plan.plan_id == self.plan_id:
            known = {s.step_id for s in self.steps}
            self.steps += [s for s in plan.steps if s.step_id not in known]
            return True
        ids = [s.step_id for s in self.steps]
        kept = ids.index(plan.applies_after) + 1 if plan.applies_after in ids else 0
        if self.plan_id:
            self.retired.add(self.plan_id)
        self.plan_id, self.steps = plan.plan_id, self.steps[:kept] + list(plan.steps)
        self.committed = kept - 1  # what the old plan still does is committed
        return True

    def commit_through(self, step_id: str) -> None:
        ids = [s.step_id for s in self.steps]
        if step_id in ids:
            self.committed = max(self.committed, ids.index(step_id))

    def cells(self) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
        """Return the cells the remaining moves visit: committed ones, then the rest."""
        committed: list[tuple[int, int]] = []
        rest: list[tuple[int, int]] = []
        for i, s in enumerate(self.steps):
            if s.step_id in self.ended or s.action != "move" or len(s.args) < 3:
                continue
            cell = _cell(s.args[2])
            if cell[0] >= 0:
                (committed if i <= self.committed else rest).append(cell)
        return committed, rest


class RerunLogger:
    """Log decoded cbdi messages to a rerun recording stream."""

    def __init__(self, rr: Any, stream: Any) -> None:
        self.rr, self.stream = rr, stream
        self.epoch, self.time = 0, 0.0
        self.colours: dict[str, tuple[int, int, int]] = {}
        self.cells: dict[str, tuple[int, int]] = {}
        self.skipped = 0
        self.tally = PlannerTally()
        self.routes: dict[str, Route] = {}
        self.modes: dict[str, str] = {}  # plan id -> search mode of its last round

    def colour(self, agent: str) -> tuple[int, int, int]:
        if agent not in self.colours:
            self.colours[agent] = ROBOT_COLOURS[len(self.colours) % len(ROBOT_COLOURS)]
        return self.colours[agent]

    def log(self, path: str, entity: Any, static: bool = False) -> None:
        self.stream.log(path, entity, static=static)

    def clock(self, epoch: int, time: float) -> None:
        self.epoch, self.time = epoch, time
        self.stream.set_time("epoch", sequence=epoch)
        self.stream.set_time("sim_time", duration=time)

    def handle(self, m: RecordedMessage) -> None:
        """Log one recorded message (unknown or undecodable ones are skipped)."""
        handler = self._handlers.get(m.schema)
        if handler is None:
            return
        try:
            handler(self, m)
        except WireError:
            self.skipped += 1

    def on_tick(self, m: RecordedMessage) -> None:
        tick = decode(m.payload, Tick, m.key)
        self.clock(tick.epoch, tick.time)

    def on_info(self, m: RecordedMessage) -> None:
        """Draw the map's floor and each of its static layers (`WorldInfo.view`), if the
        domain gave one."""
        rr, view = self.rr, decode(m.payload, WorldInfo, m.key).view
        if view is None:
            return
        self.log(
            "world/map/floor",
            rr.Boxes2D(mins=[[0, 0]], sizes=[[view.width, view.height]], colors=[(235, 235, 235)]),
            static=True,
        )
        for layer in view.layers:
            half = layer.size / 2
            labels = layer.labels if len(layer.labels) == len(layer.cells) else None
            self.log(
                f"world/map/{layer.name}",
                rr.Boxes2D(
                    centers=[(x + 0.5, y + 0.5) for x, y in layer.cells],
                    half_sizes=[(half, half)] * len(layer.cells),
                    colors=[layer.colour],
                    labels=labels,
                ),
                static=True,
            )
        self._graph(view)

    def _graph(self, view: MapView) -> None:
        """Draw a map's graph: its links as line strips (`world/graph/links`), its places
        as labelled points (`world/graph/places`)."""
        if not view.places:
            return
        rr, at = self.rr, {p.name: p.at for p in view.places}
        if view.links:
            strips = [[at[link.a], at[link.b]] for link in view.links]
            self.log(
                "world/graph/links",
                rr.LineStrips2D(strips, colors=[(150, 150, 150)], radii=0.04),
                static=True,
            )
        self.log(
            "world/graph/places",
            rr.Points2D(
                [p.at for p in view.places],
                radii=0.12,
                colors=[(90, 90, 90)],
                labels=[p.name for p in view.places],
            ),
            static=True,
        )

    def on_snapshot(self, m: RecordedMessage) -> None:
        rr, snap = self.rr, decode(m.payload, WorldSnapshot, m.key)
        self.clock(snap.epoch, snap.time)
        self.log(
            "world/robots",
            rr.Points2D(
                [a.pose for a in snap.agents],
                radii=0.35,
                colors=[self.colour(a.name) for a in snap.agents],
                labels=[f"{a.name} ({len(a.load)})" if a.load else a.name for a in snap.agents],
            ),
        )
        self.cells.update((a.name, a.cell) for a in snap.agents)
        self.log(
            "world/people",
            rr.Points2D(
                [p.pose for p in snap.people],
                radii=0.3,
                colors=[(250, 190, 40)],
                labels=[p.name for p in snap.people],
            ),
        )
        self.log(
            "world/items",
            rr.Points2D(
                [(i.cell[0] + 0.5, i.cell[1] + 0.5) for i in snap.items],
                radii=0.15,
                colors=[(120, 70, 20) if i.known else (200, 120, 60) for i in snap.items],
                labels=[i.name for i in snap.items],
            ),
        )

    def on_request(self, m: RecordedMessage) -> None:
        if keys.traced_request(m.key) != keys.world_rpc("act"):
            return
        rr, req = self.rr, decode(m.payload, ActionRequest, m.key)
        text = f"requests {req.action}" + (f" to {list(req.target)}" if req.target else "")
        self.log(f"agents/{req.agent}/log", rr.TextLog(text, level="INFO"))
        here = self.cells.get(req.agent)
        if req.action == "move" and req.target and here:
            self.log(
                f"agents/{req.agent}/intent",
                rr.Arrows2D(
                    origins=[(here[0] + 0.5, here[1] + 0.5)],
                    vectors=[(req.target[0] - here[0], req.target[1] - here[1])],
                    colors=[self.colour(req.agent)],
                ),
            )

    def on_outcome(self, m: RecordedMessage) -> None:
        rr, o = self.rr, decode(m.payload, ActionOutcome, m.key)
        level = "INFO" if o.status == "succeeded" else "WARN"
        why = f": {o.reason}" if o.reason else ""
        self.log(f"agents/{o.agent}/log", rr.TextLog(f"{o.action} {o.status}{why}", level=level))

    def on_stats(self, m: RecordedMessage) -> None:
        rr, stats = self.rr, decode(m.payload, WorldStats, m.key)
        for a in stats.agents:
            counters = {**a.counts, "failed": a.failed}
            for name, value in counters.items():  # the simulator's own, then failures
                self.log(f"plots/{a.agent}/{name}", rr.Scalars(value))

    def on_alive(self, m: RecordedMessage) -> None:
        rr, event = self.rr, decode(m.payload, Liveliness, m.key)
        service = keys.service_of_alive(event.key)
        self.log(
            "health",
            rr.TextLog(
                f"{service} {'up' if event.alive else 'down'}",
                level="INFO" if event.alive else "WARN",
            ),
        )

    def on_finished(self, m: RecordedMessage) -> None:
        done = decode(m.payload, RunFinished, m.key)
        self.log("health", self.rr.TextLog(f"run finished: {done.reason}", level="INFO"))

    def on_desire(self, m: RecordedMessage) -> None:
        rr, e = self.rr, decode(m.payload, DesireEvent, m.key)
        goal = " ".join(f"({' '.join(g)})" for g in e.goal)
        why = f": {e.reason}" if e.reason else ""
        level = "WARN" if e.event == "dropped" else "INFO"
        self.log(
            f"agents/{e.agent}/log",
            rr.TextLog(f"desire {e.desire} {e.event}{why} {goal}", level=level),
        )

    def on_plan(self, m: RecordedMessage) -> None:
        """Log a plan the planner published (a decision) or the scheduler passed on, and
        draw the route it adds to or replaces."""
        rr, plan = self.rr, decode(m.payload, PartialPlan, m.key)
        if m.key == keys.planner_plans(plan.agent):
            self._planned(m.key, plan)
        else:
            self.log(
                f"agents/{plan.agent}/log",
                rr.TextLog(
                    f"plan {plan.plan_id} (after {plan.baseline or 'nothing'}):"
                    f" {len(plan.steps)} steps"
                ),
            )
        if self.routes.setdefault(plan.agent, Route()).take(plan):
            self._draw(plan.agent)

    def _planned(self, key: str, plan: PartialPlan) -> None:
        rr, a = self.rr, plan.agent
        line = self.tally.observe(key, plan)
        end = " (complete)" if plan.complete else ""
        if line is None:
            text, level = f"planner: {plan.plan_id} +{len(plan.steps)} steps{end}", "DEBUG"
        else:
            what = f"replan #{self.tally.counts(a).replans}" if line.replan else "plan"
            after = f", after {line.applies_after}" if line.applies_after else ""
            text = f"planner: {what} {plan.plan_id} ({line.kind}{after}): "
            text += f"{len(plan.steps)} steps{end}"
            level = "WARN" if line.kind == "repair" else "INFO"
        self.log(f"agents/{a}/log", rr.TextLog(text, level=level))
        counts, published = self.tally.counts(a), self.tally.line(a, plan.plan_id)
        self.log(f"plots/{a}/planner/replans", rr.Scalars(counts.replans))
        self.log(f"plots/{a}/planner/forecast_repairs", rr.Scalars(counts.forecast_repairs))
        if published is not None:
            self.log(f"plots/{a}/planner/plan_steps", rr.Scalars(published.steps))

    def _draw(self, agent: str) -> None:
        """Draw the route's committed part thick, the rest (still repairable) thin, pale."""
        rr, route = self.rr, self.routes[agent]
        committed, rest = route.cells()
        here = self.cells.get(agent)
        start = [(here[0] + 0.5, here[1] + 0.5)] if here is not None else []
        firm = start + [(x + 0.5, y + 0.5) for x, y in committed]
        loose = firm[-1:] + [(x + 0.5, y + 0.5) for x, y in rest]
        colour = self.colour(agent)
        pale = tuple((c + 2 * 255) // 3 for c in colour)
        for part, points, radius, rgb in (
            ("committed", firm, 0.09, colour),
            ("rest", loose, 0.04, pale),
        ):
            path = f"world/plans/{agent}/{part}"
            if len(points) > 1:
                self.log(path, rr.LineStrips2D([points], colors=[rgb], radii=radius))
            else:
                self.log(path, rr.Clear(recursive=False))

    def on_search(self, m: RecordedMessage) -> None:
        rr, req = self.rr, decode(m.payload, SearchRequest, m.key)
        self.tally.observe(m.key, req)
        goal = " ".join(f"({' '.join(g)})" for g in req.goal)
        what = f" for {req.desire}: {goal}" if goal else ""
        text = f"search {req.kind} {req.request_id}{what}"
        self.log(f"agents/{req.agent}/log", rr.TextLog(text, level="DEBUG"))

    def on_round(self, m: RecordedMessage) -> None:
        rr, r = self.rr, decode(m.payload, SearchRound, m.key)
        self.tally.observe(m.key, r)
        plots = f"plots/{r.agent}/planner"
        self.log(f"{plots}/expanded", rr.Scalars(r.expanded))
        self.log(f"{plots}/round_seconds", rr.Scalars(r.seconds))
        self.log(f"{plots}/search_rounds", rr.Scalars(self.tally.counts(r.agent).search_rounds))
        if r.best_h >= 0:
            self.log(f"{plots}/best_h", rr.Scalars(r.best_h))
        before, self.modes[r.plan_id] = self.modes.get(r.plan_id, r.mode), r.mode
        search = f"planner: {r.purpose} search for {r.plan_id}"
        if r.mode != before:
            text = f"{search} falls back from {before} to {r.mode} (round {r.number})"
            self.log(f"agents/{r.agent}/log", rr.TextLog(text, level="WARN"))
        if r.kind == "exhausted":
            text = f"{search}: round {r.number} exhausted the space in mode {r.mode}"
            self.log(f"agents/{r.agent}/log", rr.TextLog(text, level="WARN"))

    def on_forecast(self, m: RecordedMessage) -> None:
        rr, f = self.rr, decode(m.payload, ForecastReport, m.key)
        self.tally.observe(m.key, f)
        seen = self.tally.counts(f.agent).forecasts
        for kind in FORECAST_KINDS:
            self.log(f"plots/{f.agent}/forecasts/{kind}", rr.Scalars(seen.get(kind, 0)))
        through = f"committed through {f.committed or 'nothing'}"
        if f.kind == "holds":
            text, level = f"forecast: {f.plan_id} holds ({through})", "DEBUG"
        else:
            at = f" at {f.failed_step}" if f.failed_step else ""
            text, level = f"forecast: {f.plan_id} {f.kind}{at} ({through}): {f.reason}", "WARN"
        self.log(f"agents/{f.agent}/log", rr.TextLog(text, level=level))
        route = self.routes.get(f.agent)
        if route is not None and route.plan_id == f.plan_id and f.committed:
            route.commit_through(f.committed)
            self._draw(f.agent)

    def on_status(self, m: RecordedMessage) -> None:
        rr, st = self.rr, decode(m.payload, ActionStatus, m.key)
        if st.status == "waiting":
            return
        why = f": {st.reason}" if st.reason else ""
        level = "INFO" if st.status in ("running", "succeeded") else "WARN"
        self.log(
            f"agents/{st.agent}/log",
            rr.TextLog(f"step {st.step_id} {st.action} {st.status}{why}", level=level),
        )
        route = self.routes.get(st.agent)
        if route is not None and any(s.step_id == st.step_id for s in route.steps):
            if st.status in ENDED:
                route.ended.add(st.step_id)
            route.commit_through(st.step_id)  # a step that started is committed
            self._draw(st.agent)

    def on_arrest(self, m: RecordedMessage) -> None:
        rr, a = self.rr, decode(m.payload, ArrestReport, m.key)
        self.log(
            f"agents/{a.agent}/log",
            rr.TextLog(
                f"early arrest of {a.plan_id} after {a.last_step or 'nothing'}; "
                f"cancelled {', '.join(a.cancelled) or 'nothing'}",
                level="WARN",
            ),
        )

    _handlers = {
        "cbdi.world.Tick/1": on_tick,
        "cbdi.world.WorldInfo/1": on_info,
        "cbdi.world.WorldSnapshot/1": on_snapshot,
        "cbdi.world.ActionRequest/1": on_request,
        "cbdi.world.ActionOutcome/1": on_outcome,
        "cbdi.world.WorldStats/1": on_stats,
        "cbdi.Liveliness/1": on_alive,
        "cbdi.RunFinished/1": on_finished,
        "cbdi.agent.DesireEvent/1": on_desire,
        "cbdi.agent.PartialPlan/1": on_plan,
        "cbdi.agent.ActionStatus/1": on_status,
        "cbdi.agent.ArrestReport/1": on_arrest,
        "cbdi.planner.SearchRequest/1": on_search,
        "cbdi.planner.SearchRound/1": on_round,
        "cbdi.planner.ForecastReport/1": on_forecast,
    }


def _cell(name: str) -> tuple[int, int]:
    parts = name.split("_")
    try:
        return (int(parts[1]), int(parts[2]))
    except (IndexError, ValueError):
        return (-1, -1)
