"""Desires pursued together: desires of one `together` and priority planned as one goal
(one trip for two jobs), each achieved, dropped and reported on its own."""

from __future__ import annotations

from pathlib import Path

import pytest

from cbdi.beliefs import fact
from cbdi.wire.world import Sensed
from cbdi_scheduler.agentfile import AgentFileError, load_agent
from cbdi_scheduler.mind import Mind, Reaction

ROOT = Path(__file__).resolve().parents[2]
JOBS = ROOT / "domains/courier/agents/courier-jobs.toml"


def sensed(
    epoch: int, *add: str, delete: tuple[str, ...] = (), time: float | None = None
) -> Sensed:
    parcels = {a.split()[1]: "parcel" for a in add if a.startswith("parcel_at")}
    return Sensed(
        agent="robot1",
        epoch=epoch,
        time=float(epoch) if time is None else time,
        instances=parcels,
        add=[a.split() for a in add],
        delete=[a.split() for a in delete],
    )


def events(out: Reaction) -> list[tuple[str, str]]:
    return [(e.desire, e.event) for e in out.events]


def searches(out: Reaction) -> list[tuple[tuple[str, ...], ...]]:
    return [
        tuple(g.atom for g in c.desire.goal)
        for c in out.commands
        if c.kind == "start_search" and c.desire is not None
    ]


def test_two_jobs_are_one_goal_and_each_is_achieved_on_its_own() -> None:
    mind = Mind(load_agent(JOBS, "robot1"))
    first = mind.on_percepts(sensed(0, "parcel_at p1 c_2_1", "parcel_at p2 c_2_1"))
    assert events(first) == [
        ("deliver_p1", "added"),
        ("deliver_p2", "added"),
        ("deliveries", "activated"),
    ]
    assert searches(first) == [(("delivered", "p1"), ("delivered", "p2"))]  # one plan
    # p1 is delivered: its desire is achieved, the intention goes on, no new search.
    one = mind.on_percepts(sensed(1, "delivered p1", delete=("parcel_at p1 c_2_1",)))
    assert events(one) == [("deliver_p1", "achieved")] and searches(one) == []
    assert mind.intentions.current is not None
    assert mind.intentions.current.desire.name == "deliveries"
    both = mind.on_percepts(sensed(2, "delivered p2", delete=("parcel_at p2 c_2_1",)))
    assert events(both) == [("deliver_p2", "achieved"), ("deliveries", "achieved")]
    assert mind.intentions.current is None and mind.desires == {}


def test_a_new_job_joins_the_goal_and_a_job_given_up_ends_the_joint_plan() -> None:
    mind = Mind(load_agent(JOBS, "robot1"))
    mind.on_percepts(sensed(0, "parcel_at p1 c_2_1"))
    more = mind.on_percepts(sensed(1, "parcel_at p2 c_5_1"))
    assert events(more) == [("deliver_p2", "added")]
    revised = [c for c in more.commands if c.kind == "start_search"]
    assert [c.reason for c in revised] == ["goal revised"]  # the planner revises: union
    assert searches(more) == [(("delivered", "p1"), ("delivered", "p2"))]
    # p1's deadline (200 s) passes first while nothing executes: it is dropped, the
    # joint intention with it, and p2 (added later, due later) is pursued on its own.
    late = mind.on_percepts(sensed(200, "parcel_at p2 c_5_1", time=200.5))
    assert ("deliver_p1", "dropped") in events(late)
    assert [c.kind for c in late.commands].count("drop") == 1
    assert searches(late) == [(("delivered", "p2"),)]
    assert mind.intentions.current is not None
    assert mind.intentions.current.desire.name == "deliveries"


def test_without_together_each_job_is_its_own_intention(tmp_path: Path) -> None:
    text = JOBS.read_text().replace(', together = "deliveries"', "")
    text = text.replace('"../pddl/domain.pddl"', f'"{JOBS.parent.parent / "pddl/domain.pddl"}"')
    alone = tmp_path / "alone.toml"
    alone.write_text(text)
    mind = Mind(load_agent(alone, "robot1"))
    first = mind.on_percepts(sensed(0, "parcel_at p1 c_2_1", "parcel_at p2 c_2_1"))
    assert searches(first) == [(("delivered", "p1"),)]  # two trips: one goal at a time
    assert ("deliver_p1", "activated") in events(first)


@pytest.mark.parametrize(
    ("together", "message"),
    [('"deliver_{p}"', "not the desire's own name"), ('"two words"', "joint intention")],
)
def test_a_bad_together_is_refused_naming_the_field(
    tmp_path: Path, together: str, message: str
) -> None:
    text = JOBS.read_text().replace('together = "deliveries"', f"together = {together}", 1)
    text = text.replace('"../pddl/domain.pddl"', f'"{JOBS.parent.parent / "pddl/domain.pddl"}"')
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    with pytest.raises(AgentFileError, match=r"rules\[0\]\.then\[0\]\.add_desire\.together"):
        load_agent(bad, "robot1")
    with pytest.raises(AgentFileError, match=message):
        load_agent(bad, "robot1")


def test_the_goal_literals_are_beliefs_of_the_domain() -> None:
    mind = Mind(load_agent(JOBS, "robot1"))
    mind.on_percepts(sensed(0, "parcel_at p1 c_2_1"))
    assert mind.beliefs.holds(fact("parcel_at", "p1", "c_2_1"))
