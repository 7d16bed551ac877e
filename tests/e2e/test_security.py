"""The authenticated, access-controlled bus (real Zenoh, real processes): a client without
credentials, or with wrong ones, cannot connect; one with robot2's credentials cannot
move robot1, add a desire to it (but as robot2's scheduler, under their group, which
its agent file asks under), finish the run or read robot1's keys; each refusal is
logged (by the router, or the world); and the run still ends as it should."""

from __future__ import annotations

import asyncio
import json
import re
import stat
from pathlib import Path

import pytest

from cbdi import keys
from cbdi.bus import BusConfig, ZenohBus, open_bus, publish, request
from cbdi.errors import ConfigError, RequestFailedError, RequestTimeoutError
from cbdi.security import read_credentials
from cbdi.wire import encode
from cbdi.wire.agent import AgentReply, AgentRequest, StateRequest
from cbdi.wire.common import RunFinished
from cbdi.wire.world import ActionReply, ActionRequest
from tests_support import BIN, Proc, free_port, wait_for

pytestmark = pytest.mark.e2e

# Keys of robot1 that robot2 shares with it as members of one group (docs/security.md).
GROUP_SHARED = {keys.scheduler_claims("robot1"), keys.epoch_ack("robot1", "scheduler")}


async def _as(endpoint: str, creds: Path) -> ZenohBus:
    found = read_credentials(creds)
    cfg = BusConfig(
        connect=(endpoint,), connect_timeout=5.0, user=found.user, password=found.password
    )
    return await open_bus(cfg)


async def _no_login(endpoint: str, creds: Path) -> list[str]:
    """Try to join without credentials and with a wrong password; return the errors."""
    errors = []
    user = read_credentials(creds).user
    for cfg in (
        BusConfig(connect=(endpoint,), connect_timeout=2.0),
        BusConfig(connect=(endpoint,), connect_timeout=2.0, user=user, password="guess"),
    ):
        with pytest.raises(ConfigError) as refused:
            await open_bus(cfg)
        errors.append(str(refused.value))
    return errors


async def _refused(bus: ZenohBus, key: str, payload: bytes) -> str:
    """Ask on `key`; return how it failed (an ACL-denied query is never answered)."""
    try:
        await bus.request(key, payload, timeout=2.0)
    except RequestTimeoutError:
        return "timeout"
    except RequestFailedError as exc:
        return f"failed: {exc}"
    return "answered"


async def _attack(endpoint: str, creds: Path) -> dict[str, object]:
    """What a client holding robot2's credentials gets when it goes for robot1."""
    out: dict[str, object] = {"no_login": await _no_login(endpoint, creds / "robot1.executor.json")}
    executor = await _as(endpoint, creds / "robot2.executor.json")
    scheduler = await _as(endpoint, creds / "robot2.scheduler.json")
    try:
        move = ActionRequest(agent="robot1", action="move", request_id="rogue-1", target=(0, 6))
        out["act_robot1"] = await _refused(executor, keys.world_act("robot1"), encode(move))
        # On its own key, naming robot1: the world refuses it.
        try:
            # An answer is due: a loaded machine may take long (5 s failed at load 9).
            await request(executor, keys.world_act("robot2"), move, ActionReply, timeout=30.0)
            out["act_own_key"] = "answered"
        except RequestFailedError as exc:
            out["act_own_key"] = exc.code
        desire = AgentRequest(
            from_agent="robot2",
            group="recyclers",
            op="add_desire",
            desire="d",
            goal=["(in robot1 c_0_6)"],
        )
        out["desire"] = [
            await _refused(executor, keys.agent_request("robot1", "recyclers"), encode(desire)),
            await _refused(scheduler, keys.agent_request("robot1", "operator"), encode(desire)),
        ]
        # Its scheduler asks robot1 under their group (the recycler's `ask_way`): that is
        # served, as robot1's allowed_groups say.
        check = AgentRequest(
            from_agent="robot2", group="recyclers", op="check_belief", belief="(map_loaded)"
        )
        key = keys.agent_request("robot1", "recyclers")
        out["group_ask"] = (await request(scheduler, key, check, AgentReply, timeout=30.0)).holds
        # The router's admin space (a session answers `@/**` of its own too).
        out["admin"] = await _refused(scheduler, "@/*/router/**", b"")
        out["state"] = await _refused(
            scheduler, keys.component_rpc("robot1", "scheduler", "state"), encode(StateRequest())
        )
        seen: list[str] = []
        ticks: list[str] = []
        sub = scheduler.subscribe(["cbdi/robot1/**", keys.world_percepts("robot1")])
        clock = scheduler.subscribe(keys.CLOCK)  # what robot2 may read still comes

        async def collect(s: object, into: list[str]) -> None:
            async for sample in s:  # type: ignore[attr-defined]
                into.append(sample.key)

        tasks = [
            asyncio.create_task(collect(sub, seen)),
            asyncio.create_task(collect(clock, ticks)),
        ]
        fake_end = RunFinished(reason="done", epoch=1, time=1.0)
        await publish(scheduler, keys.EVENTS, fake_end, block=True)
        await publish(executor, keys.world_percepts("robot1"), fake_end, block=True)
        await scheduler.declare_token(keys.alive("robot1/executor"))
        await asyncio.sleep(4.0)
        for t in tasks:
            t.cancel()
        out["read"] = sorted(set(seen) - GROUP_SHARED)
        out["ticks"] = len(ticks)
    finally:
        await executor.close()
        await scheduler.close()
    return out


def _denied(log: str, user: str, action: str, key: str) -> bool:
    pattern = (
        rf"event=acl_denied user={re.escape(user)} action={action} flow=\w+ key={re.escape(key)}"
    )
    return re.search(pattern, log) is not None


def test_a_rogue_client_is_refused_and_the_run_goes_on(tmp_path: Path) -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    run = tmp_path / "run"
    argv = [str(BIN / "cbdi"), "up", "paper-7x7", "--agents", "2", "--port", str(port)]
    launcher = Proc([*argv, "--speed", "1", "--json", "--run-dir", str(run)], tmp_path / "up.log")
    creds = run / "credentials"
    try:
        wait_for(
            lambda: "started service=robot2/executor" in launcher.output(),
            timeout=90,
            what="the run to start",
        )
        assert stat.S_IMODE((creds / "robot1.executor.json").stat().st_mode) == 0o600
        assert stat.S_IMODE(run.stat().st_mode) == 0o700
        before = launcher.output()
        attack = asyncio.run(_attack(endpoint, creds))
        assert launcher.alive(), "a fake RunFinished ended the run"
        wait_for(lambda: not launcher.alive(), timeout=240, what="the run to end")
    finally:
        code = launcher.stop()
    log = launcher.log_path.read_text()
    assert code == 0, log[-3000:]
    summary = json.loads(log[log.index("{\n") :])
    assert summary["result"] == "done" and summary["stats"]["litter_recycled"] == 3

    no_login = attack["no_login"]
    assert all("cannot join Zenoh" in e for e in no_login), no_login  # type: ignore[union-attr]
    assert "as user 'robot1.executor'" in no_login[1]  # type: ignore[index]
    assert attack["act_robot1"] == "timeout"
    assert attack["act_own_key"] == "not_own_agent"
    assert attack["desire"] == ["timeout", "timeout"]
    assert attack["group_ask"] is True
    assert attack["state"] == attack["admin"] == "timeout"
    assert attack["read"] == [], attack["read"]
    assert attack["ticks"], "robot2's credentials still read the clock"
    assert not (run / "credentials").exists(), "the run's secrets outlive it"

    # Each refusal is in the router's log (the world's, for an action on the wrong key).
    assert "event=auth_refused" in log
    assert _denied(log, "robot2.executor", "query", keys.world_act("robot1"))
    assert _denied(log, "robot2.executor", "query", keys.agent_request("robot1", "recyclers"))
    assert not _denied(log, "robot2.scheduler", "query", keys.agent_request("robot1", "recyclers"))
    assert _denied(log, "robot2.scheduler", "query", keys.agent_request("robot1", "operator"))
    assert _denied(log, "robot2.scheduler", "put", keys.EVENTS)
    assert _denied(log, "robot2.scheduler", "query", "@/*/router/**")
    assert _denied(log, "robot2.executor", "put", keys.world_percepts("robot1"))
    assert _denied(log, "robot2.scheduler", "declare_subscriber", keys.world_percepts("robot1"))
    assert _denied(log, "robot2.scheduler", "liveliness_token", keys.alive("robot1/executor"))
    assert "event=act_refused key=cbdi/world/rpc/act/robot2 agent=robot1" in log
    # Nothing of the run itself was refused (before the attack, nor of another user).
    assert "acl_denied" not in before, before[-3000:]
    others = [line for line in log.splitlines() if "acl_denied" in line and "robot2." not in line]
    assert not others, others[:5]


async def _receive(bus: ZenohBus, expr: str, want: str, send: object, seconds: float) -> bool:
    """Subscribe to `expr` on `bus`, then call `send()` every 0.2 s until a sample on
    `want` arrives or `seconds` pass; return whether it arrived."""
    sub = bus.subscribe(expr)

    async def first() -> None:
        async for sample in sub:
            if sample.key == want:
                return

    waiting = asyncio.ensure_future(first())
    try:
        async with asyncio.timeout(seconds):
            while not waiting.done():
                await send()  # type: ignore[operator]
                await asyncio.sleep(0.2)
        return True
    except TimeoutError:
        return False
    finally:
        waiting.cancel()


def test_joined_routers_carry_a_secured_run_and_refuse_a_rogue(tmp_path: Path) -> None:
    """A run split over two hosts (`cbdi compose --join`), on loopback: the joining router
    logs in to the hub as `router`, and knows the hub by its Zenoh id (the run's
    secrets). What robot2's services send on the joining router reaches the hub's side
    and back; robot2's credentials still cannot write robot1's keys there."""
    from cbdi.security import create_secrets, grants
    from cbdi.security.policy import COMPOSE_GRANTS

    agents = [(a, ("planner", "scheduler", "executor")) for a in ("robot1", "robot2")]
    secrets = create_secrets(tmp_path / "secrets", [*grants(agents), *COMPOSE_GRANTS])
    hub, joiner = free_port(), free_port()
    rules = ["--users", str(secrets.users), "--acl", str(secrets.acl)]
    router = [str(BIN / "cbdi"), "router", "--heartbeat", "0"]
    a = Proc([*router, "--listen", f"tcp/127.0.0.1:{hub}", "--zenoh-config",
              str(secrets.hub), *rules], tmp_path / "hub.log")  # fmt: skip
    b = Proc([*router, "--listen", f"tcp/127.0.0.1:{joiner}", "--connect",
              f"tcp/127.0.0.1:{hub}", "--credentials", str(secrets.credentials("router")),
              *rules], tmp_path / "joiner.log")  # fmt: skip
    creds = secrets.root / "credentials"
    forged = keys.agent_stream("robot1", "executor", "status")

    async def check() -> dict[str, bool]:
        at_hub, at_joiner = f"tcp/127.0.0.1:{hub}", f"tcp/127.0.0.1:{joiner}"
        monitor = await _as(at_hub, creds / "monitor.json")
        scheduler = await _as(at_hub, creds / "robot2.scheduler.json")
        planner = await _as(at_joiner, creds / "robot2.planner.json")
        rogue = await _as(at_joiner, creds / "robot2.executor.json")
        status = keys.agent_stream("robot2", "planner", "status")
        plans = keys.scheduler_plans("robot2")
        try:
            out = {
                "joiner_to_hub": await _receive(
                    monitor, f"{keys.ROOT}/**", status, lambda: planner.publish(status, b"\x90"), 20
                ),
                "hub_to_joiner": await _receive(
                    planner,
                    f"{keys.ROOT}/robot2/**",
                    plans,
                    lambda: scheduler.publish(plans, b"\x90"),
                    20,
                ),
                "forged_arrives": await _receive(
                    monitor, f"{keys.ROOT}/**", forged, lambda: rogue.publish(forged, b"\x90"), 3
                ),
            }
        finally:
            for bus in (monitor, scheduler, planner, rogue):
                await bus.close()
        return out

    try:
        wait_for(lambda: "event=routing" in a.output() + "" and "event=routing" in b.output(),
                 timeout=30, what="both routers")  # fmt: skip
        out = asyncio.run(check())
    finally:
        a.stop()
        b.stop()
    joined = b.log_path.read_text()
    logs = a.log_path.read_text() + joined
    assert out == {"joiner_to_hub": True, "hub_to_joiner": True, "forged_arrives": False}, (
        out,
        logs[-4000:],
    )
    assert "acl_no_subject" not in logs, logs[-4000:]
    assert _denied(joined, "robot2.executor", "put", forged), joined[-4000:]
