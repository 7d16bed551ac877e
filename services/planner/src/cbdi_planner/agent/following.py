"""What the online planner keeps of the lines it published (`Following`): each step's
status and start time as the executor reports them, and the lines the executing one took
over from, whose steps may still run (a robot mid-drive): a new search follows those
(`running_line`), its task reaches them (`held`), and the steps that follow them start
from the state they leave (`followed`). `ContinualPlanner` is one.
"""

from __future__ import annotations

from cbdi.wire.agent import ActionStatus
from cbdi_planner.agent.errors import UnknownPlanError
from cbdi_planner.agent.lines import Line, Search, followed, held, plan_prefix, running_line
from cbdi_planner.pddl.ast import Domain
from cbdi_planner.state import State
from cbdi_planner.task import Task

__all__ = ["PREVIOUS", "Following"]

PREVIOUS = 8  # lines kept that the executing one follows (`Following.previous`)
DISPATCHED = ("running", "succeeded", "failed", "refused")  # the executor took it up
ENDED = "succeeded"  # a step known to have ended (its effects, if any, in the beliefs)


class Following:
    """The lines of one agent's planner, followed as they execute."""

    agent: str
    domain: Domain
    now: float
    plan_prefix: str
    line: Line | None
    # The lines `line` took over from (latest last): the steps it follows may still run
    # there, and a new plan follows them too.
    previous: list[Line]
    published: set[str]  # every plan id sent, for the statuses' sake
    _search: Search | None  # the search in progress (its line's statuses count too)

    def held(self) -> list[tuple[str, ...]]:
        """The facts the running steps started from (`lines.held`)."""
        return held(self.domain, [self.line, *self.previous])

    def followed(self, task: Task, line: Line) -> State | None:
        """The state the running steps `line` follows leave (`lines.followed`)."""
        return followed(task, line, self.previous, self.now)

    def running_line(self) -> Line | None:
        """The line whose step runs now: the executing one, or one it follows."""
        return running_line([self.line, *reversed(self.previous)])

    @staticmethod
    def search_follows_nothing(line: Line) -> bool:
        """Whether no step of `line` runs (a new search need not follow it)."""
        return not line.running()

    def on_status(self, status: ActionStatus) -> None:
        """Record a step's status for the commitment and the forecast.

        Raise UnknownPlanError for a plan this planner never published (statuses of
        replaced plans are expected and ignored).
        """
        if status.plan_id not in self.published:
            if (
                self.plan_prefix != plan_prefix(self.agent, 0)
                and status.plan_id.startswith(plan_prefix(self.agent, 0))
                and not status.plan_id.startswith(self.plan_prefix)
            ):
                return  # a predecessor's plan, still being reported on: not ours to track
            raise UnknownPlanError(status.plan_id, status.step_id)
        repairs = self._search.repairs if self._search else None
        lines = [line for line in (self.line, *self.previous, repairs) if line is not None]
        for line in lines:
            if status.plan_id == line.plan_id and status.step_id in line.step_ids:
                k = line.step_ids.index(status.step_id)
                line.statuses[k] = status.status
                if status.status == "running":
                    line.began[k] = status.time  # the world's start time
        if status.status in DISPATCHED:
            # The executor dispatched a step of this plan (or refused it when due): what
            # other plans ran before it has ended, whatever its last status said (an
            # executor killed mid-step never reports that step's end).
            for line in lines:
                if line.plan_id != status.plan_id:
                    ended = {k: ENDED for k, st in line.statuses.items() if st == "running"}
                    line.statuses.update(ended)
