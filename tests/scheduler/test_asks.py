"""Agents that ask each other (issue 30): a rule's `ask` effect, sent once when its rule
starts to match, served by the asked agent before its next epoch's percepts; and the
recycler's rules on the corridor map, where one robot parked in the way is asked to
make way (`ask_way`, `give_way`, `forget_way_asked`)."""

from __future__ import annotations

import asyncio
from dataclasses import replace
from pathlib import Path

import pytest
from cbdi_recycling.events import OBSTACLE_MEMORY, believe_others, seen_others
from cbdi_recycling.knowledge import RecyclingKnowledge
from cbdi_recycling.maps import load_map
from cbdi_recycling.wire import AgentSeen, Percepts
from cbdi_recycling.world import AgentSpec, World

import cbdi_scheduler.asking as asking
from cbdi import keys
from cbdi.beliefs import BeliefSet, fact
from cbdi.bus import MemoryNetwork, request
from cbdi.errors import WireError
from cbdi.runtime.together import Together, TogetherService
from cbdi.security.policy import grants
from cbdi.wire import decode, encode
from cbdi.wire.agent import AgentReply, AgentRequest
from cbdi_scheduler.agentfile import AgentFileError, load_agent
from cbdi_scheduler.desires import Desire
from cbdi_scheduler.mind import Mind
from cbdi_scheduler.requests import prepare_request, serve_request
from cbdi_scheduler.rules import Ask, ReactiveRule, RuleEffect, fire_rules
from cbdi_scheduler.service import SchedulerSettings, scheduler_main
from tests_support import REPO

AGENT = REPO / "domains/recycling/agents/recycler.toml"
CORRIDOR = REPO / "domains/recycling/maps/corridor-pass-8x3.toml"
DOMAIN = REPO / "domains/recycling/pddl/domain.pddl"
WAY_ASKED = fact("way_asked", "robot2")


def corridor(robot1: tuple[int, int], robot2: tuple[int, int]) -> World:
    """The corridor map with robot1 and robot2 on the given cells (the bin at (0,1),
    the side pocket at (2,2)) and no litter: nobody has work but what a test gives."""
    specs = [AgentSpec("robot1", robot1), AgentSpec("robot2", robot2)]
    return World(replace(load_map(CORRIDOR), litter={}), specs, seed=0)


def mind_in(world: World, agent: str) -> Mind:
    mind = Mind(load_agent(AGENT, agent))
    mind.beliefs = mind.beliefs.adding(mind.knowledge.map_beliefs(world.info()))
    return mind


def at(world: World, agent: str, epoch: int) -> Percepts:
    p = world.percepts(agent)
    return Percepts(
        agent=p.agent,
        epoch=epoch,
        time=float(epoch),
        position=p.position,
        depth=p.depth,
        free=p.free,
        blocked=p.blocked,
        items=p.items,
        holding=p.holding,
        others=p.others,
    )


def agent_file(tmp_path: Path, body: str, group: str = 'group = "team"') -> Path:
    path = tmp_path / "a.toml"
    path.write_text(
        f'domain = "{DOMAIN}"\n{group}\nallowed_groups = ["team"]\n'
        f'private_predicates = ["asked"]\n{body}',
        encoding="utf-8",
    )
    return path


ASK_RULE = """
[[rules]]
name = "ask"
when = [["(in {self} {c})", "(free {c})"]]
then = [{ ask = { agent = "bob", add_belief = "(asked {self})" } }]
"""


# -- the agent file ----------------------------------------------------------------------
def test_an_ask_effect_is_read_with_its_agent_and_belief(tmp_path: Path) -> None:
    spec = load_agent(agent_file(tmp_path, ASK_RULE), "ann")
    (effect,) = spec.rules[0].effects
    assert (effect.target, effect.op, effect.agent) == ("ask", "ADD", "bob")
    assert effect.belief == fact("asked", "ann")


@pytest.mark.parametrize(
    ("ask", "group", "why"),
    [
        ('{ agent = "bob", add_belief = "(asked x)" }', "", "set `group`"),
        ('{ agent = "9bob", add_belief = "(asked x)" }', 'group = "team"', "must start with"),
        ('{ agent = "bob" }', 'group = "team"', "one of add_belief, del_belief"),
        (
            '{ agent = "bob", add_belief = "(asked x)", del_belief = "(asked x)" }',
            'group = "team"',
            "one of add_belief, del_belief",
        ),
        ('{ agent = "bob", add_belief = "(asked x)", op = 1 }', 'group = "team"', "'op'"),
        ('{ agent = "bob", add_belief = "(= (loaded_amount x) 1)" }', 'group = "team"', "fact"),
        ('{ agent = "bob", add_belief = "(askd x)" }', 'group = "team"', "'askd' is not"),
        ('{ add_belief = "(asked x)" }', 'group = "team"', "agent: missing"),
    ],
)
def test_a_bad_ask_is_refused_naming_the_field(
    tmp_path: Path, ask: str, group: str, why: str
) -> None:
    body = f'[[rules]]\nwhen = [["(map_loaded)"]]\nthen = [{{ ask = {ask} }}]\n'
    with pytest.raises(AgentFileError, match="rules\\[0\\]\\.then\\[0\\]\\.ask") as err:
        load_agent(agent_file(tmp_path, body, group), "ann")
    assert why in str(err.value)


# -- rules and the mind ------------------------------------------------------------------
def test_an_ask_is_bound_per_binding_and_made_once_per_firing() -> None:
    rule = ReactiveRule(
        condition=((),),
        effects=(RuleEffect("ask", "ADD", belief=fact("asked", "ann"), agent="bob"),) * 2,
    )
    out = fire_rules([rule], BeliefSet.of([]), {}, 0.0)
    assert out.asks == [Ask("bob", "ADD", fact("asked", "ann"))]
    assert out.beliefs == BeliefSet.of([]) and out.desires == {}


def test_the_mind_sends_an_ask_when_its_rule_starts_to_match_not_while_it_matches(
    tmp_path: Path,
) -> None:
    mind = Mind(load_agent(agent_file(tmp_path, ASK_RULE), "ann"))
    mind.beliefs = BeliefSet.of([fact("in", "ann", "c_0_0"), fact("free", "c_0_0")])
    first = mind.on_percepts(_empty("ann", 0))
    assert first.asks == [Ask("bob", "ADD", fact("asked", "ann"))]
    mind.request_beliefs([fact("free", "c_1_1")], [])  # the rules fire again: still matches
    assert mind.on_percepts(_empty("ann", 1)).asks == []
    mind.request_beliefs([], [fact("free", "c_0_0")])  # no longer matches
    assert mind.on_percepts(_empty("ann", 2)).asks == []
    mind.request_beliefs([fact("free", "c_0_0")], [])  # matches again: asked again
    assert mind.on_percepts(_empty("ann", 3)).asks == first.asks


def test_an_agent_never_asks_itself(tmp_path: Path) -> None:
    mind = Mind(load_agent(agent_file(tmp_path, ASK_RULE.replace('"bob"', '"{self}"')), "ann"))
    mind.beliefs = BeliefSet.of([fact("in", "ann", "c_0_0"), fact("free", "c_0_0")])
    assert mind.on_percepts(_empty("ann", 0)).asks == []


def _empty(agent: str, epoch: int) -> Percepts:
    return Percepts(
        agent=agent,
        epoch=epoch,
        time=float(epoch),
        position=(0, 0),
        depth=0,
        free=[],
        blocked=[],
        items=[],
        holding=[],
    )


# -- requests: checked at once, applied now or before the next epoch ----------------------
def test_a_request_is_checked_at_once_and_applied_when_asked(tmp_path: Path) -> None:
    mind = Mind(load_agent(agent_file(tmp_path, ""), "bob"))
    req = AgentRequest(from_agent="ann", group="team", op="add_belief", belief="(asked ann)")
    served = prepare_request(mind, req)
    assert served.reply.accepted and served.apply is not None
    assert not mind.beliefs.holds(fact("asked", "ann"))
    served.apply()
    assert mind.beliefs.holds(fact("asked", "ann"))
    bad = prepare_request(mind, AgentRequest(from_agent="ann", group="team", op="add_belief"))
    assert not bad.reply.accepted and bad.apply is None
    stranger = AgentRequest(from_agent="x", group="gang", op="add_belief", belief="(asked x)")
    assert not serve_request(mind, stranger).accepted


def test_held_asks_land_before_the_percepts_of_the_epoch_after_the_askers() -> None:
    done: list[str] = []
    held = asking.HeldAsks()
    held.take(4, 3, lambda: done.append("early"))  # came before we handled epoch 4
    held.take(4, 4, lambda: done.append("late"))  # came after: the same epoch anyway
    held.take(-1, 4, lambda: done.append("operator"))  # no epoch: at once
    held.take(2, 4, lambda: done.append("behind"))  # we are past it: at once
    assert done == ["operator", "behind"]
    held.release(4)
    assert done == ["operator", "behind"]
    held.release(5)
    assert done == ["operator", "behind", "early", "late"]  # in the order they came
    held.release(6)
    assert len(done) == 4


def test_a_request_epoch_is_bounded_on_the_wire() -> None:
    req = AgentRequest(from_agent="ann", group="team", op="add_belief", belief="(a)", epoch=-2)
    with pytest.raises(WireError):
        decode(encode(req), AgentRequest)
    assert (
        decode(encode(AgentRequest(from_agent="a", group="g", op="halt")), AgentRequest).epoch == -1
    )


async def test_an_ask_reaches_the_other_scheduler_and_lands_before_its_next_epoch(
    tmp_path: Path,
) -> None:
    network = MemoryNetwork()
    path = agent_file(tmp_path, "")
    settings = SchedulerSettings(agent="bob", agent_file=str(path), load_map=False)
    bob = Mind(load_agent(path, "bob"))
    shell = TogetherService("bob/scheduler", settings, scheduler_main(bob, settings))
    task = asyncio.create_task(Together([shell], network, log_level="error").run())
    bus = network.bus()
    try:
        async with asyncio.timeout(10):
            while keys.alive("bob/scheduler") not in network.tokens:
                await asyncio.sleep(0.01)
        bob.epoch = 4  # bob has handled epoch 4; ann asks in her epoch 4
        ask = AgentRequest(
            from_agent="ann", group="team", op="add_belief", belief="(asked ann)", epoch=4
        )
        reply = await request(bus, keys.agent_request("bob", "team"), ask, AgentReply)
        assert reply.accepted and not bob.beliefs.holds(fact("asked", "ann"))
        await bus.publish(keys.world_percepts("bob"), encode(_empty("bob", 5)))
        async with asyncio.timeout(10):
            while not bob.beliefs.holds(fact("asked", "ann")):
                await asyncio.sleep(0.01)
        assert bob.epoch == 5
        unknown = AgentRequest(from_agent="ann", group="team", op="add_belief", belief="(x)")
        refused = await request(bus, keys.agent_request("bob", "team"), unknown, AgentReply)
        assert not refused.accepted and "'x' is not declared" in refused.reason
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def test_an_unanswered_ask_is_logged_and_the_asker_goes_on(tmp_path: Path) -> None:
    network = MemoryNetwork()
    path = agent_file(tmp_path, ASK_RULE)
    settings = SchedulerSettings(agent="ann", agent_file=str(path), load_map=False)
    ann = Mind(load_agent(path, "ann"))
    ann.beliefs = BeliefSet.of([fact("in", "ann", "c_0_0"), fact("free", "c_0_0")])
    shell = TogetherService("ann/scheduler", settings, scheduler_main(ann, settings))
    old, asking.ASK_TIMEOUT = asking.ASK_TIMEOUT, 0.2
    task = asyncio.create_task(Together([shell], network, log_level="error").run())
    bus = network.bus()
    try:
        async with asyncio.timeout(10):
            while keys.alive("ann/scheduler") not in network.tokens:
                await asyncio.sleep(0.01)
        await bus.publish(keys.world_percepts("ann"), encode(_empty("ann", 0)))
        await bus.publish(keys.world_percepts("ann"), encode(_empty("ann", 1)))
        async with asyncio.timeout(10):  # bob is nowhere: ann goes on to epoch 1
            while ann.epoch < 1:
                await asyncio.sleep(0.01)
        assert not task.done()
    finally:
        asking.ASK_TIMEOUT = old
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


# -- the recycler on the corridor --------------------------------------------------------
def test_the_recycling_knowledge_believes_which_robot_it_saw_where_for_a_while() -> None:
    world = corridor((2, 1), (3, 1))
    p = world.percepts("robot2")
    assert p.others == [AgentSeen(name="robot1", cell=(2, 1))]
    seen = seen_others({"robot3": ("c_5_5", -OBSTACLE_MEMORY)}, p)
    assert seen == {"robot1": ("c_2_1", 0.0)}  # robot3, unseen for 8 s, is forgotten
    beliefs = believe_others(BeliefSet.of([fact("other_in", "robot3", "c_5_5")]), seen)
    assert sorted(beliefs.facts_of("other_in")) == [("other_in", "robot1", "c_2_1")]
    far = corridor((2, 1), (5, 1))
    assert far.percepts("robot2").others == []
    knowledge = RecyclingKnowledge("robot2")
    knowledge.on_percepts(BeliefSet.of([]), p)
    later = at(far, "robot2", 7)  # robot1 out of sight: still believed where last seen
    assert knowledge.on_percepts(BeliefSet.of([]), later).holds(fact("other_in", "robot1", "c_2_1"))
    gone = at(far, "robot2", 8)
    assert not knowledge.on_percepts(BeliefSet.of([]), gone).facts_of("other_in")


def test_a_stalled_robot_asks_the_robot_it_sees_once_and_does_not_step_aside() -> None:
    world = corridor((2, 1), (3, 1))
    mind = mind_in(world, "robot2")
    mind.on_percepts(at(world, "robot2", 0))
    mind.request_desire(Desire("recycle", (fact("in", "robot2", "c_1_1"),), 0.8, 100.0))
    mind.on_percepts(at(world, "robot2", 1))
    mind.on_search_failed("robot1 in the way", blocked=True)
    asks: list[tuple[int, Ask]] = []
    added: list[str] = []
    for epoch in range(2, 16):  # robot1 stands still: nothing changes
        out = mind.on_percepts(at(world, "robot2", epoch))
        asks += [(epoch, a) for a in out.asks]
        added += [e.desire for e in out.events if e.event == "added"]
    assert asks == [(10, Ask("robot1", "ADD", WAY_ASKED))]  # once, when the wait stalled
    assert "step_aside" not in added  # it sees the robot in its way: it asks instead


def test_an_idle_robot_asked_to_make_way_goes_into_the_pocket_not_next_to_the_bin() -> None:
    world = corridor((2, 1), (3, 1))
    mind = mind_in(world, "robot1")
    mind.on_percepts(at(world, "robot1", 0))
    mind.request_beliefs([WAY_ASKED], [])
    out = mind.on_percepts(at(world, "robot1", 1))
    assert ("give_way", "activated") in [(e.desire, e.event) for e in out.events]
    assert mind.desires["give_way"].goal == (fact("in", "robot1", "c_2_2"),)  # not c_1_1
    assert not mind.beliefs.holds(WAY_ASKED)  # one ask, one move


def test_a_robot_at_work_declines_and_the_ask_lapses() -> None:
    world = corridor((2, 1), (3, 1))
    mind = mind_in(world, "robot1")
    mind.on_percepts(at(world, "robot1", 0))
    mind.request_desire(Desire("recycle", (fact("in", "robot1", "c_1_1"),), 0.8, 100.0))
    mind.on_percepts(at(world, "robot1", 1))
    mind.request_beliefs([WAY_ASKED], [])
    events: list[tuple[str, str]] = []
    for epoch in range(2, 14):
        out = mind.on_percepts(at(world, "robot1", epoch))
        events += [(e.desire, e.event) for e in out.events]
    assert ("give_way", "added") in events and ("give_way", "activated") not in events
    assert ("give_way", "dropped") in events  # its deadline passed
    assert mind.intentions.current is not None
    assert mind.intentions.current.desire.name == "recycle"


def test_an_ask_the_robot_cannot_follow_is_forgotten_once_the_asker_is_out_of_sight() -> None:
    world = corridor((1, 1), (2, 1))  # robot1 at the dead end by the bin: nowhere to go
    mind = mind_in(world, "robot1")
    mind.on_percepts(at(world, "robot1", 0))
    mind.request_beliefs([WAY_ASKED], [])
    mind.on_percepts(at(world, "robot1", 1))
    assert mind.beliefs.holds(WAY_ASKED) and "give_way" not in mind.desires
    gone = corridor((1, 1), (5, 1))
    mind.on_percepts(at(gone, "robot1", 2))
    mind.on_percepts(at(gone, "robot1", 3))
    assert not mind.beliefs.holds(WAY_ASKED)


# -- security ----------------------------------------------------------------------------
def test_a_scheduler_may_ask_under_its_own_group_only() -> None:
    agents = [("robot1", ("planner", "scheduler", "executor"))]
    found = {g.identity: g for g in grants(agents, {"robot1": "recyclers"})}
    scheduler, executor = found["robot1/scheduler"], found["robot1/executor"]
    assert keys.agent_request("*", "recyclers") in scheduler.query
    assert scheduler.groups == ("recyclers",)
    assert keys.agent_request("*", "recyclers") not in executor.query and not executor.groups
    for reserved in ("operator", "sensors"):
        claimed = {g.identity: g for g in grants(agents, {"robot1": reserved})}
        assert not claimed["robot1/scheduler"].groups
        assert keys.agent_request("*", reserved) not in claimed["robot1/scheduler"].query


def test_only_an_agent_file_that_asks_gets_its_group_granted() -> None:
    from cbdi.launcher.scenario import agent_groups, find_scenario, load_scenario

    corridor_pass = load_scenario(
        find_scenario(str(REPO / "domains/recycling/scenarios/corridor-pass.toml"))
    )
    assert agent_groups(corridor_pass) == {"robot1": "recyclers", "robot2": "recyclers"}
    courier = load_scenario(find_scenario(str(REPO / "domains/courier/scenarios/courier.toml")))
    assert agent_groups(courier) == {"robot1": "couriers", "robot2": "couriers"}  # ask_way
    pair = load_scenario(find_scenario(str(REPO / "domains/courier/scenarios/courier-pair.toml")))
    assert agent_groups(pair) == {}  # courier-jobs.toml has a group but never asks
