"""The bus's security, without a network: who may do what, the secrets on disk, and the
reading of the router's refusals from Zenoh's log."""

from __future__ import annotations

import io
import json
import stat
from pathlib import Path

import pytest
import zenoh

from cbdi import keys
from cbdi.bus.zenoh_bus import BusConfig, zenoh_config
from cbdi.errors import ConfigError
from cbdi.runtime.log import Log
from cbdi.security import acl_config, create_secrets, discover, grants, read_credentials, run_dir
from cbdi.security.denials import Denial, DenialLog, parse
from cbdi.security.policy import Grant

AGENTS = [
    ("robot1", ("planner", "scheduler", "executor")),
    ("robot2", ("planner", "scheduler", "executor")),
]


def _meet(a: str, b: str) -> bool:
    return bool(zenoh.KeyExpr(a).intersects(zenoh.KeyExpr(b)))


def _by_id() -> dict[str, Grant]:
    return {g.identity: g for g in grants(AGENTS)}


def test_only_the_world_writes_world_state_events_and_percepts() -> None:
    for identity, g in _by_id().items():
        for expr in g.publish:
            for key in (keys.EVENTS, keys.CLOCK, keys.SNAPSHOT, keys.world_percepts("robot1")):
                assert not _meet(expr, key) or identity == "world", (identity, expr, key)


def test_only_an_agents_executor_and_body_ask_for_its_actions() -> None:
    askers = {
        i for i, g in _by_id().items() if any(_meet(q, keys.world_act("robot1")) for q in g.query)
    }
    assert askers == {"robot1/executor", "robot1/performer"}


def test_an_agents_services_write_only_their_own_keys_and_read_only_the_shared_ones() -> None:
    shared = {keys.scheduler_claims_all(), keys.epoch_ack("*", "scheduler"), keys.ALIVE_ALL}
    for identity, g in _by_id().items():
        if not identity.startswith("robot2/"):
            continue
        for expr in (*g.publish, *g.serve, *g.tokens, *g.query):
            assert "robot1" not in expr and not _meet(expr, "cbdi/robot1/scheduler/rpc/request/x")
        for expr in g.read:
            assert expr in shared or not _meet(expr, "cbdi/robot1/**"), (identity, expr)


def test_the_acl_denies_by_default_and_names_each_identity_by_its_user() -> None:
    acl = acl_config(grants(AGENTS))
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    users = {s["id"]: s["usernames"] for s in acl["subjects"]}
    assert users["robot1.executor"] == ["robot1.executor"] and "operator" in users
    rule_ids = {r["id"] for r in acl["rules"]}
    assert all(set(p["rules"]) <= rule_ids for p in acl["policies"])
    assert len(rule_ids) == len(acl["rules"])
    every_rule = [r for r in acl["rules"] if r["permission"] != "allow" or not r["key_exprs"]]
    assert not every_rule
    # Every rule on a key has its rule on the advanced pub/sub keys below it.
    robot1 = next(r for r in acl["rules"] if r["id"] == "robot1.planner:read")
    assert (
        "cbdi/robot1/**" in robot1["key_exprs"] and "cbdi/robot1/**/@adv/**" in robot1["key_exprs"]
    )


def test_secrets_are_private_random_and_read_back(tmp_path: Path) -> None:
    secrets = create_secrets(tmp_path / "run", grants(AGENTS))
    path = secrets.credentials("robot1/executor")
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert stat.S_IMODE((tmp_path / "run").stat().st_mode) == 0o700
    for f in (secrets.users, secrets.acl):
        assert stat.S_IMODE(f.stat().st_mode) == 0o600
    found = read_credentials(path)
    assert found.user == "robot1.executor" and len(found.password) >= 24
    assert found.password not in repr(found)
    lines = secrets.users.read_text().splitlines()
    assert f"robot1.executor:{found.password}" in lines and len(lines) == len(grants(AGENTS))
    other = create_secrets(tmp_path / "again", grants(AGENTS))
    assert read_credentials(other.credentials("robot1/executor")).password != found.password
    assert read_credentials(secrets.credentials("operator")).groups == ("operator",)
    assert json.loads(secrets.acl.read_text()) == acl_config(grants(AGENTS))
    secrets.remove()
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("", "credentials"),
        ("[1]", "credentials"),
        ('{"user": "u"}', "password"),
        ('{"user": "a:b", "password": "p"}', "user"),
        ('{"user": "u", "password": "p", "groups": 3}', "groups"),
    ],
)
def test_a_bad_credentials_file_is_refused_naming_the_file_and_field(
    tmp_path: Path, text: str, field: str
) -> None:
    path = tmp_path / "c.json"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        read_credentials(path)
    assert err.value.field == field and str(path) in str(err.value)
    with pytest.raises(ConfigError, match="file not found"):
        read_credentials(tmp_path / "none.json")


def test_a_local_run_is_found_from_its_routers_port(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("CBDI_RUNS_DIR", str(tmp_path))
    assert discover(["tcp/127.0.0.1:7555"], "operator") is None
    secrets = create_secrets(run_dir(7555), grants(AGENTS))
    found = discover(["tcp/127.0.0.1:7555"], "operator")
    assert found == secrets.credentials("operator")


def test_a_session_with_a_user_logs_in_with_it() -> None:
    conf = zenoh_config(BusConfig(user="robot1.executor", password="s3cret"))
    assert json.loads(conf.get_json("transport/auth/usrpwd/user")) == "robot1.executor"
    assert "s3cret" not in repr(BusConfig(user="u", password="s3cret"))


ZID_A, ZID_B = "625ac42e499365e48558d5976bb9d801", "a4781e334e8b82394d478766a47d0ab3"
TARGET = "zenoh::net::routing::interceptor::access_control: "


def _line(thread: int, text: str) -> str:
    return f"2026-12-03T14:14:17.149Z TRACE rx-1 ThreadId({thread}) {TARGET}{text}"


def test_refusals_are_read_from_zenohs_log_and_the_cache_worked_out_is_not() -> None:
    out = io.StringIO()
    denials = DenialLog(Log("router", stream=out))
    subject = f"Interface(lo)+Username(bob)+Transport(Tcp)+{ZID_B}"
    lines = [
        _line(9, "ACL (ingress): caching permissions for `a` ..."),
        _line(9, f"{ZID_B} on {subject} is unauthorized to Query (ingress) on a"),
        _line(9, f"{ZID_B} on {subject} is unauthorized to Put (ingress) on a"),
        _line(8, f"{ZID_B} on {subject} is unauthorized to Put (ingress) on a/x"),
        _line(8, f"Using cached result: {ZID_B} is unauthorized to Put (ingress) on a"),
        _line(8, f"Using cached result: {ZID_B} is unauthorized to Put (ingress) on a"),
        _line(8, f"Using cached result: {ZID_B} is unauthorized to Put (ingress) on a"),
        _line(8, f"{ZID_A} on Username(alice) is authorized to Put (ingress) on a/public"),
    ]
    for line in lines:
        denials.line(line)
    put_a = Denial("bob", "put", "ingress", "a")
    assert denials.counts == {Denial("bob", "put", "ingress", "a/x"): 1, put_a: 3}
    logged = out.getvalue().splitlines()
    assert len(logged) == 3  # the 1st and 2nd on `a` (powers of two), and `a/x`
    assert "event=acl_denied user=bob action=put flow=ingress key=a/x count=1" in logged[0]


def test_a_declaration_and_a_failed_login_are_logged_too() -> None:
    out = io.StringIO()
    denials = DenialLog(Log("router", stream=out))
    text = f"{ZID_B} on Username(r2) is unauthorized to Declare Subscriber (ingress) on cbdi/r1/**"
    parsed = parse(_line(9, text), {})
    declared = Denial("r2", "declare_subscriber", "ingress", "cbdi/r1/**")
    assert parsed == (declared, "Declare Subscriber")
    accept = "zenoh_transport::unicast::establishment::accept"
    denials.line(
        f"DEBUG acc-0 ThreadId(05) {accept}: UsrPwd extension - Recv OpenSyn. Invalid password."
    )
    assert 'event=auth_refused reason="Recv OpenSyn. Invalid password" count=1' in out.getvalue()


def test_rules_zenoh_does_not_take_are_refused_naming_the_setting() -> None:
    bad = {"enabled": True, "rules": [{"id": "x", "messages": ["fly"], "key_exprs": ["a/**"]}]}
    with pytest.raises(ConfigError) as err:
        zenoh_config(BusConfig(mode="router", connect=(), extra={"access_control": bad}))
    assert err.value.field == "access_control" and "unknown variant `fly`" in str(err.value)
