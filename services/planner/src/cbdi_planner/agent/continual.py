"""The planner service's online mode: continual planning for one agent (pure core).

`ContinualPlanner` turns inputs (search requests, beliefs, the executor's step statuses)
into messages to publish, and owns the search in progress (`search`), whose rounds the
service runs in a worker thread (`round()`, then `after_round()` on the loop).

Lines (one plan id each) and searches are `cbdi_planner.agent.lines`', the tasks it
plans (from the beliefs or a request's problem) `cbdi_planner.agent.tasks`'; a repair,
a revised goal or an improvement starts a new line from the committed state.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from itertools import count

from msgspec.structs import replace

from cbdi.agentfile import PlanningSettings
from cbdi.beliefs import BeliefSet
from cbdi.wire.agent import PartialPlan
from cbdi.wire.base import Message
from cbdi.wire.planner import SearchRequest, SearchRound, SearchStatus
from cbdi_planner.agent.errors import BadRequestError
from cbdi_planner.agent.following import PREVIOUS, Following
from cbdi_planner.agent.grounded import Groundings, reaches_goal
from cbdi_planner.agent.lines import (
    Line,
    Purpose,
    Search,
    extend,
    forecast_report,
    plan_prefix,
    round_report,
    search_status,
    sent_own_plan,
)
from cbdi_planner.agent.problem import (
    GoalError,
    check_goal,
)
from cbdi_planner.agent.tasks import AgentTasks
from cbdi_planner.agent.transient import Transients
from cbdi_planner.continual import (
    FAILS_LATER,
    HOLDS,
    NG,
    Event,
    G,
    ImprovedPlan,
    ModeChanged,
    PartialPlanFound,
    RoundBound,
    RoundDone,
    SearchFailed,
    SearchThread,
    Sensed,
    commit,
    forecast,
)
from cbdi_planner.continual.improver import Improver
from cbdi_planner.errors import PlannerError, Unsolvable
from cbdi_planner.pddl.ast import Domain
from cbdi_planner.plan import Plan
from cbdi_planner.state import State, initial_state
from cbdi_planner.task import Task

__all__ = ["ContinualPlanner"]

Log = Callable[..., None]


class ContinualPlanner(Following, AgentTasks):
    """The continual planner of one agent."""

    def __init__(
        self,
        agent: str,
        domain: Domain,
        settings: PlanningSettings,
        grid: float = 1.0,
        log: Log | None = None,
        improve: bool = True,
        transients: Transients | None = None,
        life: int = 0,
    ) -> None:
        self.agent, self.domain, self.settings, self.grid = agent, domain, settings, grid
        # A restarted planner (`life` restarts so far) numbers its plans apart from its
        # predecessors', whose plans the executor may still report on.
        self.plan_prefix = plan_prefix(agent, life)
        self.transients = transients or Transients()
        self.groundings = Groundings(domain, self.transients)
        self.log: Log = log or (lambda *a, **k: None)
        self.improve = improve
        self.beliefs = BeliefSet()
        self.now = 0.0
        self.request: SearchRequest | None = None
        self.line: Line | None = None
        self.previous: list[Line] = []  # see `Following`
        self._search: Search | None = None
        self.last_forecast: tuple[str, str, str] = ("", "", "")
        self.repair_trigger = ""
        self.ids = count(1)
        self.published: set[str] = set()  # every plan id sent, for the statuses' sake
        # A request's problem `warm` read ahead: (the request, its beliefs and goal).
        self._read: tuple[SearchRequest, tuple[BeliefSet, list[list[str]]]] | None = None

    @property
    def search(self) -> Search | None:
        """The search in progress (None: none)."""
        return self._search

    @search.setter
    def search(self, new: Search | None) -> None:
        old = self._search
        if old is not None and old is not new and isinstance(old.thread, Improver):
            old.thread.close()  # its worker thread stops
        self._search = new

    # -- inputs ---------------------------------------------------------------------------
    def on_request(self, req: SearchRequest) -> list[Message]:
        """Start, revise (the union of goals) or cancel the search.

        Raise BadRequestError (after the searching state is left as it was) for a problem
        that does not parse or a goal the domain cannot express.
        """
        try:
            if not req.problem:
                check_goal(self.domain, req.goal)  # before the searching state changes
            return self._on_request(self._with_problem(req))
        except Unsolvable as exc:
            # Nothing reaches the goal from these beliefs (grounding): a failed search,
            # blocked if only something that moves is in the way.
            if req.kind == "start":
                self.search = None
                if self.line is None or self.search_follows_nothing(self.line):
                    self.line = None
            goal = self.request.goal if self.request is not None else req.goal
            return [self._failure(req.request_id, str(exc), goal)]
        except (GoalError, PlannerError) as exc:
            raise BadRequestError(req.request_id, str(exc)) from exc

    def _on_request(self, req: SearchRequest) -> list[Message]:
        if req.kind == "cancel":
            # The lines stay: a step of theirs may run (its status may be on its way),
            # and the next search follows it.
            self.request, self.search = None, None
            return [self._status(req.request_id, "cancelled")]
        same = self.request is not None and req.request_id == self.request.request_id
        if (
            req.kind == "start"
            and same
            and self.request is not None
            and [list(g) for g in req.goal] == [list(g) for g in self.request.goal]
        ):
            return []  # the same request again (sent when we appeared): on it already
        if req.kind == "revise" and self.request is not None:
            goal = [list(g) for g in self.request.goal]
            goal += [list(g) for g in req.goal if list(g) not in goal]
            req = replace(req, request_id=self.request.request_id, goal=goal)
            self.request = req
            if self.line is not None and self.line.steps:
                return self._revise_from_committed(req.goal)
        executing = self.running_line()
        self.request = replace(req, kind="start")
        self.line, self.last_forecast, self.repair_trigger = None, ("", "", ""), ""
        self.previous = []
        if executing is not None:
            # A step of the executing plan runs (a robot mid-drive): the new plan starts
            # from the state it leaves and follows it (the executor lets it end).
            self.line = executing  # its running steps are in the task (`held`)
            task = self.task(req.goal)
            self._from_committed(Purpose.NEW, task, min_commit_steps=0)
            search = self.search
            if search is not None:
                if not reaches_goal(task, search.thread.state):
                    self.search = None  # the line stays: a retry follows the step too
                    raise Unsolvable("no action reaches the goal from these beliefs (relaxed)")
                return [self._status(req.request_id, "searching")]
            self.line = None
        task = self.request_task(req.goal)
        line = Line(self._plan_id(), Purpose.NEW, self.at_grid(self.now))
        self.search = Search(
            self._thread(task, initial_state(task)), line, Purpose.NEW, req.request_id
        )
        return [self._status(req.request_id, "searching")]

    def _revise_from_committed(self, goal: list[list[str]]) -> list[Message]:
        """Search for the revised `goal` from the executing line's committed state;
        raise Unsolvable if the goal is out of reach from there, even relaxed."""
        task = self.task(goal)
        out = self._from_committed(Purpose.REVISE, task)
        search = self.search
        if search is not None and not reaches_goal(task, search.thread.state):
            self.search = None
            raise Unsolvable("no action reaches the goal from these beliefs (relaxed)")
        return out

    def on_beliefs(self, beliefs: BeliefSet, now: float) -> list[Message]:
        """New beliefs: forecast the executing plan's failure and act on it."""
        self.beliefs, self.now = beliefs, max(self.now, now)
        self.transients.see(beliefs)
        line, req = self.line, self.request
        if line is None or req is None or not line.steps:
            return []
        if self.search is not None and (
            self.search.purpose in (Purpose.REPAIR, Purpose.REVISE)
            or self.search.repairs is not None
        ):
            return []  # a repair, or a new plan following the running step, is on its way
        try:
            task = self.task(req.goal)
        except (GoalError, PlannerError) as exc:
            # Nothing reaches the goal from these beliefs (a robot boxed in by people):
            # no repair can help now; the executing plan goes on until it fails.
            self.log("forecast_skipped", plan=line.plan_id, reason=str(exc))
            return []
        fc = forecast(
            task,
            line.steps,
            line.statuses,
            min_commit_steps=self.settings.min_commit_steps,
            horizon=self.settings.forecast_horizon,
            sensed=Sensed(self.now, line.began),
            start=self.followed(task, line),
        )
        failed = line.step_ids[fc.failed] if fc.failed is not None else ""
        out: list[Message] = []
        key = (fc.kind, failed, fc.reason)
        if key != self.last_forecast:
            self.last_forecast = key
            out.append(forecast_report(self.agent, line, fc, self.now))
        if fc.kind == FAILS_LATER and f"{failed}:{fc.reason}" != self.repair_trigger:
            self.repair_trigger = f"{failed}:{fc.reason}"
            self.log("forecast_failure", plan=line.plan_id, step=failed, reason=fc.reason)
            out += self._from_committed(Purpose.REPAIR, task)
        elif (
            fc.kind == HOLDS
            and self.improve
            and line.complete
            and not line.improved
            and self.search is None
            and fc.commitment.state is not None
            and any(st in ("running", "succeeded") for st in line.statuses.values())
        ):
            # Only a line that executes: a line still waiting for the one it replaces
            # may itself be replaced before its committed part runs.
            line.improved = True
            rest = line.makespan_after(fc.commitment.count)
            out += self._from_committed(Purpose.IMPROVE, task, improve_on=rest)
        return out

    def _from_committed(
        self,
        purpose: Purpose,
        task: Task,
        improve_on: float = math.inf,
        min_commit_steps: int | None = None,
        mode: str = G,
        whole: bool = False,
    ) -> list[Message]:
        """Start a search (`mode`, `whole`: `SearchThread`'s) from the committed state of
        the executing line (the started steps and `min_commit_steps` more)."""
        line, req = self.line, self.request
        assert line is not None and req is not None
        if min_commit_steps is None:
            min_commit_steps = self.settings.min_commit_steps
        start = self.followed(task, line)
        sensed = Sensed(self.now, line.began)
        done = commit(task, line.steps, line.statuses, min_commit_steps, sensed, start)
        state: State | None = done.state
        if state is None:
            self.log("commit_failed", plan=line.plan_id, reason=done.reason)
            return []
        after = line.step_ids[done.count - 1] if done.count else ""
        ends = [self.on_grid(a.time) + (a.duration or 0.0) for a in line.steps[: done.count]]
        if start is not None and not done.count:  # after the running steps it follows
            after = line.applies_after
            running = [a for p in self.previous for a in p.running()]
            ends += [self.on_grid(a.time) + (a.duration or 0.0) for a in running]
        origin = self.at_grid(max([self.now, *ends]))
        new = Line(self._plan_id(), purpose, origin, baseline=after, applies_after=after)
        thread: SearchThread | Improver
        if purpose == Purpose.IMPROVE:
            thread = Improver(
                task,
                state,
                prefix=done.count,
                improve_on=improve_on,
                budget=self.settings.improve_expansions,
            )
        else:
            thread = self._thread(task, state, prefix=done.count, mode=mode, whole=whole)
        self.search = Search(thread, new, purpose, req.request_id, repairs=line)
        self.log("search_from_committed", purpose=purpose, plan=new.plan_id, after=after)
        return []

    def _thread(
        self, task: Task, state: State, prefix: int = 0, mode: str = G, whole: bool = False
    ) -> SearchThread:
        settings = self.settings
        return SearchThread(
            task,
            state,
            prefix,
            empty_rounds=settings.empty_rounds,
            agenda=settings.agenda,
            mode=mode,
            whole=whole,
        )

    # -- rounds ---------------------------------------------------------------------------
    def round(self, search: Search, expansions: int | None = None) -> list[Event]:
        """Run one round of `search` (call from a worker thread).

        `expansions` (virtual time) bounds the round by node expansions only: what is
        left of the epoch's budget, at most `expansions_per_round`.
        """
        bound = self.bound()
        if expansions is not None:
            per_round = bound.expansions or expansions
            bound = RoundBound(None, max(1, min(per_round, expansions)), bound.plan_size)
        events = search.thread.step(bound)
        request = self.request
        if request is not None and any(isinstance(e, SearchFailed) for e in events):
            # Tell blocked from unsolvable here, in the worker thread: it grounds the task.
            search.blocked = self._blocked(request.goal)
        return events

    def after_round(self, search: Search, events: list[Event]) -> list[Message]:
        """Turn a round's events into messages; drop a search replaced meanwhile."""
        if search is not self.search:
            return []
        outdated = self._outdated(search, events)
        if outdated is not None:
            return outdated
        out: list[Message] = []
        better: ImprovedPlan | None = None
        for event in events:
            if isinstance(event, RoundDone):
                out.append(self._round(search, event))
            elif isinstance(event, PartialPlanFound):
                out.append(self._publish(search, event.plan, event.complete))
                if event.complete:
                    out.append(self._status(search.request_id, "done"))
            elif isinstance(event, ImprovedPlan):
                better = event  # a round may find several: the last is the best
            elif isinstance(event, ModeChanged):
                self.log("fall_back", plan=search.line.plan_id, mode=event.mode)
                if sent_own_plan(search, self.line):
                    # Alg. 2 lines 11-14: the complete search starts over from the
                    # committed state, not after the greedy partial plans already out
                    # (they may lead where the goal is out of reach: a battery spent).
                    return out + self._again_from_committed(
                        search, self.settings.min_commit_steps, NG
                    )
            elif isinstance(event, SearchFailed):
                if not event.proved and sent_own_plan(search, self.line):
                    # Exhausted after its own partial plans, which proves nothing: search
                    # the whole space from the committed state (`SearchThread.whole`).
                    self.log("search_whole", plan=search.line.plan_id)
                    return out + self._again_from_committed(
                        search, self.settings.min_commit_steps, NG, whole=True
                    )
                out += self._failed(search, event.reason)
        if better is not None and self.search is search:
            # Lines 23-24: the best plan of the round replaces the executing one after
            # the committed part. The search ends here: what it would find next starts
            # from a committed part execution is about to leave behind, so the next
            # improvement starts afresh from the new plan's committed part.
            improved = Plan(better.plan.actions)
            self.log(
                "improved", plan=search.line.plan_id, makespan=improved.makespan, than=better.than
            )
            out.append(self._publish(search, improved, True))
            self.search = None
        if search.thread.finished and self.search is search:
            self.search = None
        return out

    def _outdated(self, search: Search, events: list[Event]) -> list[Message] | None:
        """Drop `search` if execution committed past its prefix (Alg. 2 line 9): its
        rounds' reports, and a new plan's search again after what runs now. None: it
        is not outdated."""
        if search.repairs is None:
            return None
        old = search.repairs
        started = sum(1 for s in old.statuses.values() if s in ("running", "succeeded"))
        if started <= search.thread.prefix:
            return None
        self.log("outdated", plan=search.line.plan_id, purpose=search.purpose)
        self.search, self.repair_trigger = None, ""
        self.last_forecast = ("", "", "")
        rounds: list[Message] = [self._round(search, e) for e in events if isinstance(e, RoundDone)]
        if search.purpose == Purpose.NEW:
            # A new plan must come: search again (as searched) after what runs now.
            whole = isinstance(search.thread, SearchThread) and search.thread.whole
            return rounds + self._again_from_committed(search, 0, NG if whole else G, whole)
        return rounds

    def _again_from_committed(
        self, search: Search, min_commit_steps: int, mode: str = G, whole: bool = False
    ) -> list[Message]:
        """Replace `search` (a new plan's) by one from the committed state of the
        executing line; report the search failed if there is no committed state."""
        request = self.request
        if request is None or self.line is None:
            return []
        self.search = None
        try:
            task = self.task(request.goal)
        except (GoalError, PlannerError) as exc:
            return self._failed(search, str(exc))
        self._from_committed(
            Purpose.NEW, task, min_commit_steps=min_commit_steps, mode=mode, whole=whole
        )
        if self.search is None:
            return self._failed(search, "the executing plan's committed part cannot be simulated")
        return []

    def _failed(self, search: Search, reason: str) -> list[Message]:
        self.search = None
        if search.purpose in (Purpose.REPAIR, Purpose.IMPROVE) and self.line is not None:
            self.log("repair_failed", plan=search.line.plan_id, reason=reason)
            return []  # the executing plan goes on; execution reports if it fails
        goal = self.request.goal if self.request is not None else []
        return [self._failure(search.request_id, reason, goal, search.blocked)]

    def _publish(self, search: Search, plan: Plan, complete: bool) -> PartialPlan:
        line = search.line
        if (search.purpose != Purpose.NEW or search.repairs is not None) and not line.steps:
            if self.line is not None and self.line is not line:
                self.previous = [*self.previous, self.line][-PREVIOUS:]
            self.line = line  # the new line takes over from the committed point
            self.last_forecast = ("", "", "")
            self.repair_trigger = ""
        elif self.line is None:
            self.line = line
        self.published.add(line.plan_id)
        return extend(self.agent, self.domain, search, plan, complete, self.on_grid)

    def _round(self, search: Search, r: RoundDone) -> SearchRound:
        return round_report(self.agent, search, r, self.now)

    def _status(self, request_id: str, status: str, reason: str = "") -> SearchStatus:
        return search_status(self.agent, request_id, status, reason)

    def _plan_id(self) -> str:
        return f"{self.plan_prefix}{next(self.ids)}"
