"""Agent files: the shipped recycler loads; literals read; mistakes name file and field."""

from __future__ import annotations

from pathlib import Path

import pytest

from cbdi.agentfile import read_agent_file
from cbdi.beliefs import BeliefSet, fact, fluent, instance
from cbdi_scheduler.agentfile import AgentFileError, load_agent, parse_agent
from cbdi_scheduler.literals import LiteralSyntaxError, parse_belief, parse_literal
from cbdi_scheduler.rules import fire_rules

AGENTS = Path(__file__).resolve().parents[2] / "domains" / "recycling" / "agents"


def test_literals_and_beliefs_read_the_pddl_way() -> None:
    assert parse_belief("(map_loaded)") == fact("map_loaded")
    assert parse_belief("pla61 - plastic") == instance("pla61", "plastic")
    assert parse_belief("(= (loaded_amount r) 2)") == fluent("loaded_amount", "r", value=2)
    assert parse_literal("(not (holding r *))").check == "F"
    assert parse_literal("(exists {x} - plastic)").belief == instance("{x}", "plastic")
    lt = parse_literal("(< (loaded_amount r) 3)")
    assert (lt.check, lt.value) == ("LT", 3.0)
    with pytest.raises(LiteralSyntaxError, match="one expression in parentheses"):
        parse_literal("pla61 - plastic")  # an instance is a belief, not a check
    for bad in ["(free c", "free c)", "", "(= (f) x)", "(exists x plastic)"]:
        with pytest.raises(LiteralSyntaxError):
            parse_literal(bad) if "exists" in bad else parse_belief(bad)
    for bad in ["( (holding r *))", "((<) (f) 3)", "((not) (f))"]:  # a list where a word goes
        with pytest.raises(LiteralSyntaxError):
            parse_literal(bad)
        with pytest.raises(LiteralSyntaxError):
            parse_belief(bad)


def test_the_recycler_is_the_papers_plastic_agent() -> None:
    a = load_agent(AGENTS / "recycler.toml", "robot1")
    assert a.domain.name == "domain.pddl" and a.planning.mode == "online"
    assert a.preemption == "clean_preempt" and a.group == "recyclers"
    assert read_agent_file(AGENTS / "recycler.toml", "robot1").transient == ("free",)
    beliefs = BeliefSet.of(a.beliefs)
    assert beliefs.holds(instance("robot1", "robot"))
    assert beliefs.fluents[("loaded_amount", "robot1")] == 0
    sensed = beliefs.adding(
        [
            instance("pla61", "plastic"),
            fact("litter_pose", "pla61", "c_6_1"),
            instance("pla9", "plastic"),
            fact("holding", "robot1", "pla9"),
        ]
    )
    out = fire_rules(a.rules, sensed, {}, now=0)
    assert set(out.desires["recycle"].goal) == {fact("recycled", "pla61"), fact("recycled", "pla9")}


def write(tmp_path: Path, body: str) -> Path:
    (tmp_path / "d.pddl").write_text("(define (domain d))")
    p = tmp_path / "a.toml"
    p.write_text('domain = "d.pddl"\n' + body)
    return p


@pytest.mark.parametrize(
    ("body", "field", "reason"),
    [
        ('beliefs = ["(free c"]\n', "beliefs[0]", "missing ')'"),
        ("beliefs = [3]\n", "beliefs[0]", "expected str"),
        ('[scheduler]\npreemption = "sometimes"\n', "scheduler.preemption", "one of"),
        ('[scheduler]\nwait_stall_counts = "always"\n', "scheduler.wait_stall_counts", "'quiet'"),
        ("[scheduler]\nwait_stall_spread = -1\n", "scheduler.wait_stall_spread", "from 0 to 4"),
        ("[scheduler]\nwait_stall_spread = nan\n", "scheduler.wait_stall_spread", "from 0 to 4"),
        ('[planning]\nmode = "dreaming"\n', "planning.mode", "one of"),
        ("[planning]\nrounds = 3\n", "planning.rounds", "unknown setting"),
        ('[[desires]]\nname = "x"\n', "desires[0].goal", "missing"),
        (
            '[[rules]]\nwhen = [["(a)"]]\nthen = [{ explode = 1 }]\n',
            "rules[0].then[0]",
            "unknown effect",
        ),
        ('[[rules]]\nwhen = [["(a"]]\nthen = []\n', "rules[0].when[0]", "missing ')'"),
        ('transient_predicates = ["fre"]\n', "transient_predicates[0]", "no predicate 'fre'"),
        ("transient_predicates = [3]\n", "transient_predicates[0]", "a predicate name"),
        ('transient_predicates = "free"\n', "transient_predicates", "a list"),
        ('knowledge = "warehouse"\n', "knowledge", "no domain knowledge 'warehouse'"),
        ("[execution]\ncondition_wait = -1\n", "execution.condition_wait", ">= 0"),
        ('[execution]\ncondition_wait = "2"\n', "execution.condition_wait", "got str"),
        ("[execution]\nwait = 2\n", "execution.wait", "unknown setting"),
        (
            "[execution.condition_wait_for]\nfly = 2\n",
            "execution.condition_wait_for.fly",
            "no action 'fly'",
        ),
    ],
)
def test_mistakes_name_the_field(tmp_path: Path, body: str, field: str, reason: str) -> None:
    with pytest.raises(AgentFileError) as err:
        load_agent(write(tmp_path, body), "r")
    assert err.value.field == field and reason in err.value.reason
    assert str(err.value).startswith(str(tmp_path / "a.toml"))


def test_missing_domain_and_file(tmp_path: Path) -> None:
    with pytest.raises(AgentFileError, match="domain: no such file"):
        parse_agent('domain = "none.pddl"', "x.toml", "r", tmp_path)
    with pytest.raises(AgentFileError, match="file"):
        load_agent(tmp_path / "none.toml", "r")


def test_the_domain_knowledge_comes_from_the_domain_package(tmp_path: Path) -> None:
    from cbdi_recycling.knowledge import RecyclingKnowledge

    from cbdi_scheduler.knowledge import available, load_knowledge
    from cbdi_scheduler.mind import Mind

    assert "recycling" in available()
    spec = load_agent(write(tmp_path, 'knowledge = "recycling"\n'), "r")
    assert spec.knowledge == "recycling"
    mind = Mind(spec)
    assert isinstance(mind.knowledge, RecyclingKnowledge) and mind.knowledge.agent == "r"
    assert load_knowledge("recycling", "r2") is not load_knowledge("recycling", "r2")  # per agent


def test_the_execution_settings_reach_the_executor(tmp_path: Path) -> None:
    (tmp_path / "d.pddl").write_text(
        "(define (domain d) (:action go :parameters () :precondition () :effect ()))"
    )
    p = tmp_path / "a.toml"
    p.write_text(
        'domain = "d.pddl"\n[execution]\ncondition_wait = 2\n'
        "[execution.condition_wait_for]\nGo = 0.5\n"
    )
    execution = read_agent_file(p, "r").execution
    assert execution.condition_wait == 2.0 and execution.condition_wait_for == (("go", 0.5),)
    assert execution.executor_args() == [
        "--condition-wait",
        "2.0",
        "--condition-wait-for",
        "go=0.5",
    ]
    assert read_agent_file(write(tmp_path, ""), "r").execution.executor_args() == []
