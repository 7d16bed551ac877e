"""An offline search in virtual time expands only what the epochs have paid for."""

from __future__ import annotations

import threading
from pathlib import Path

from cbdi_planner.agent.backends import Counted, plan_counted
from cbdi_planner.agent.pacing import Pacer
from cbdi_planner.pddl import parse_domain, parse_problem
from cbdi_planner.pddl.ast import Domain, Problem

ROOT = Path(__file__).resolve().parents[2]
RECYCLING = ROOT / "domains/recycling"


def paced(pacer: Pacer, out: list[Counted], domain: Domain, problem: Problem) -> None:
    """The offline service's search thread: the search, then the end (whatever it was)."""
    try:
        out.append(plan_counted(domain, problem, 20000, pace=pacer.pace))
    finally:
        pacer.end()


def test_a_paced_search_ends_in_the_epoch_its_expansions_are_paid_off() -> None:
    domain = parse_domain((RECYCLING / "pddl/domain.pddl").read_text(), "domain.pddl")
    problem = parse_problem((RECYCLING / "problems/paper-7x7.pddl").read_text(), domain, "p")
    whole = plan_counted(domain, problem, 20000)  # unpaced: what it costs
    assert whole.plan is not None and whole.expanded > 30

    pacer, out = Pacer(), []
    thread = threading.Thread(target=paced, args=(pacer, out, domain, problem), daemon=True)
    thread.start()
    try:
        budget, epochs = 10, 0
        while True:
            epochs += 1
            if pacer.pay(budget):
                break
            assert not out and pacer.used == epochs * budget  # it waits for the next epoch
    finally:
        pacer.cancel()
    thread.join(5)
    (result,) = out
    assert result.plan is not None and result.expanded == whole.expanded
    assert result.plan.actions == whole.plan.actions  # the same search, only paced
    assert epochs == -(-whole.expanded // budget)  # the epoch the old debt was paid off


def test_a_cancelled_search_stops_at_its_next_expansion() -> None:
    domain = parse_domain((RECYCLING / "pddl/domain.pddl").read_text(), "domain.pddl")
    problem = parse_problem((RECYCLING / "problems/paper-7x7.pddl").read_text(), domain, "p")
    pacer, out = Pacer(), []
    thread = threading.Thread(target=paced, args=(pacer, out, domain, problem), daemon=True)
    thread.start()
    assert not pacer.pay(5)
    pacer.cancel()
    thread.join(5)
    assert not thread.is_alive() and out[0].plan is None and out[0].timeout


def test_when_ffs_budget_runs_out_the_goal_agenda_tries_with_as_much_again() -> None:
    """24 items on the 30x30 campus: FF's climbing and best-first find no plan within
    700 expansions; the goal agenda then does, and both searches are charged."""
    domain = parse_domain((RECYCLING / "pddl/domain.pddl").read_text(), "domain.pddl")
    problem = parse_problem((RECYCLING / "problems/campus-30x30.pddl").read_text(), domain, "c")
    counted = plan_counted(domain, problem, 700)
    assert counted.plan is not None and not counted.error
    assert counted.expanded > 700  # the first search's 700 and more
