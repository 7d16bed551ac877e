"""Key layout: per-agent streams, world streams, liveliness, and name validation."""

from __future__ import annotations

import pytest
import zenoh

from cbdi import keys


def test_agent_stream_layout() -> None:
    assert keys.agent_stream("robot1", "planner", "plans") == "cbdi/robot1/planner/plans"
    assert keys.agent_ack("robot1") == "cbdi/robot1/executor/ack"


def test_wildcards_match_what_they_should() -> None:
    expr = zenoh.KeyExpr(keys.agent_ack_all())
    assert expr.intersects(zenoh.KeyExpr(keys.agent_ack("r2")))
    agent_expr = zenoh.KeyExpr(keys.world_for_agent("r2"))
    assert agent_expr.intersects(zenoh.KeyExpr(keys.world_percepts("r2")))
    assert agent_expr.intersects(zenoh.KeyExpr(keys.world_outcomes("r2")))
    assert not agent_expr.intersects(zenoh.KeyExpr(keys.world_percepts("r3")))


def test_liveliness_round_trip() -> None:
    sid = keys.service_id("executor", "robot1")
    assert keys.service_of_alive(keys.alive(sid)) == "robot1/executor"
    assert zenoh.KeyExpr(keys.ALIVE_ALL).intersects(zenoh.KeyExpr(keys.alive("world")))


def test_trace_keys_stay_under_root() -> None:
    assert keys.trace(keys.world_rpc("act")) == "cbdi/trace/world/rpc/act"


@pytest.mark.parametrize("bad", ["", "1robot", "a/b", "a*", "world", "x" * 70, "r b"])
def test_bad_agent_names_are_refused(bad: str) -> None:
    with pytest.raises(ValueError, match="name"):
        keys.validate_name(bad)


@pytest.mark.parametrize(
    ("key", "agent", "component", "stream"),
    [
        ("cbdi/robot1/planner/plans", "robot1", "planner", "plans"),
        ("cbdi/world/percepts/robot2", "robot2", "world", "percepts/robot2"),
        ("cbdi/world/clock", "", "world", "clock"),
        ("cbdi/alive/robot1/executor", "robot1", "executor", "alive"),
        ("cbdi/alive/world", "", "world", "alive"),
        ("cbdi/heartbeat/robot1/planner", "robot1", "planner", "heartbeat"),
        ("cbdi/heartbeat/router", "", "router", "heartbeat"),
        ("cbdi/launcher/health", "", "launcher", "health"),
        ("cbdi/trace/world/rpc/act/request", "", "trace", "world/rpc/act/request"),
        ("cbdi/launcher/run", "", "launcher", "run"),
        ("other/thing", "", "", "other/thing"),
    ],
)
def test_describe_names_the_parts_of_a_key(
    key: str, agent: str, component: str, stream: str
) -> None:
    assert keys.describe(key) == {"agent": agent, "component": component, "stream": stream}


def test_scoped_request_keys_name_who_may_ask() -> None:
    assert keys.world_act("robot1") == "cbdi/world/rpc/act/robot1"
    assert keys.world_rpc_scope("cbdi/world/rpc/act/robot1", "act") == "robot1"
    assert keys.world_rpc_scope(keys.world_rpc("act"), "act") == ""
    assert keys.agent_request("robot1", "operator") == "cbdi/robot1/scheduler/rpc/request/operator"
    assert keys.request_group(keys.agent_request("robot1", "operator")) == "operator"
    assert keys.request_group(keys.component_rpc("robot1", "scheduler", "request")) == ""
    assert keys.request_group("cbdi/robot1/scheduler/rpc/state/x") == ""


def test_the_wide_expressions_keep_their_strings() -> None:
    assert keys.ALL == "cbdi/**"
    assert keys.owned("robot1/executor") == "cbdi/robot1/executor/**"
    assert keys.owned("robot1") == "cbdi/robot1/**"
    assert keys.trace(keys.owned("world")) == "cbdi/trace/world/**"
    assert keys.service_rpc("robot1/scheduler", "**") == "cbdi/robot1/scheduler/rpc/**"
    assert keys.advanced(keys.ALL, "sub/**") == "cbdi/**/@adv/sub/**"
    assert keys.agent_request("robot1", "**") == "cbdi/robot1/scheduler/rpc/request/**"


def test_traced_requests_and_replies() -> None:
    act = keys.world_rpc("act")
    assert keys.trace_request(act) == "cbdi/trace/world/rpc/act/request"
    assert keys.trace_reply(act) == "cbdi/trace/world/rpc/act/reply"
    assert keys.traced_request(keys.trace_request(act)) == act
    assert keys.traced_request(keys.trace_reply(act)) == ""
    assert keys.traced_request(act) == ""
    pick = keys.component_rpc("robot1", "performer", "pick")
    assert keys.is_request_to(keys.traced_request(keys.trace_request(pick)), "performer")
    assert not keys.is_request_to(act, "performer")
    assert not keys.is_request_to(keys.agent_stream("robot1", "performer", "outcomes"), "performer")


def test_stream_and_ack_tests() -> None:
    assert keys.is_stream(keys.scheduler_plans("r2"), "scheduler", "plans")
    assert not keys.is_stream(keys.planner_plans("r2"), "scheduler", "plans")
    assert keys.is_ack(keys.epoch_ack("r2", "planner")) and keys.is_ack(keys.agent_ack("r2"))
    assert not keys.is_ack(keys.executor_status("r2"))


def test_one_matcher_for_the_memory_bus_and_the_epoch_gate() -> None:
    assert keys.matches(keys.agent_ack_all(), keys.agent_ack("r2"))
    assert keys.matches(keys.ALL, keys.CLOCK) and keys.matches("cbdi/**", "cbdi")
    assert keys.matches(keys.world_for_agent("r2"), keys.world_percepts("r2"))
    assert not keys.matches(keys.world_for_agent("r2"), keys.world_percepts("r3"))
    assert not keys.matches(keys.epoch_ack("*", "scheduler"), keys.epoch_ack("r2", "planner"))
    with pytest.raises(ValueError, match="Zenoh"):
        keys.matches(keys.ALL, "cbdi//x")
