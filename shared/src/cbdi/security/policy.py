"""Who may do what on the bus: one `Grant` per identity, and the router's ACL built from them.

Pure: no file, no network. The router enforces the result with Zenoh's own access
control (`access_control`, default deny), its subjects matched by the user names that
Zenoh's user-password authentication (`transport/auth/usrpwd`) proved. docs/security.md
says what each identity may do and why.

Zenoh's advanced publishers and subscribers (`zenoh.ext`) talk on keys of their own
below a verbatim chunk, `<key>/@adv/pub/<zid>/<eid>/_` (a publisher's liveliness token,
cache queryable and heartbeats) and `<key>/@adv/sub/<zid>/<eid>/_` (a subscriber's
token). `**` does not match a chunk that starts with `@`, so every rule on `K` comes with
its rule on `K/@adv/...`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from cbdi import keys

__all__ = [
    "COMPOSE_GRANTS",
    "LAUNCHER",
    "MONITOR",
    "OPERATOR",
    "OPERATOR_GROUP",
    "PERFORMER",
    "SENSOR_GROUP",
    "VIEWER",
    "WORLD",
    "Grant",
    "acl_config",
    "grants",
    "user_of",
]

WORLD, MONITOR, LAUNCHER, OPERATOR = "world", "monitor", "launcher", "operator"
VIEWER = "viewer"  # `cbdi view --live` and `--text`: reads everything, writes nothing
PERFORMER = "performer"  # per agent: its performers and sensors (`cbdi.performer`, `cbdi.sensor`)
HUB_GRANT, HUB_SUBJECT = "router", "hub"  # the grant a joined hub router has, at the joiner
OPERATOR_GROUP, SENSOR_GROUP = "operator", "sensors"  # the groups `cbdi ctl` and sensors ask under

_PUT = ("put", "delete")
_DECLARATIONS = (
    "declare_subscriber",
    "declare_queryable",
    "liveliness_token",
    "declare_liveliness_subscriber",
)
_SUBSCRIBE = ("declare_subscriber", "declare_liveliness_subscriber", "liveliness_query")
_ALL = (*_PUT, *_DECLARATIONS, "query", "reply", "liveliness_query")


@dataclass(frozen=True)
class Grant:
    """What one identity (a service id such as `robot1/executor`, or `operator`) may do.

    `publish`: put on these keys (and run advanced publishers on them); `read`: subscribe
    to them and receive what is put; `serve`: answer requests; `query`: ask; `tokens`:
    declare liveliness tokens; `groups`: the groups it may ask agents under (the key
    `cbdi/<agent>/scheduler/rpc/request/<group>`, in `query` too).
    """

    identity: str
    publish: tuple[str, ...] = ()
    read: tuple[str, ...] = ()
    serve: tuple[str, ...] = ()
    query: tuple[str, ...] = ()
    tokens: tuple[str, ...] = ()
    groups: tuple[str, ...] = ()

    @property
    def user(self) -> str:
        return user_of(self.identity)


def user_of(identity: str) -> str:
    """Return the Zenoh user name of an identity (`robot1/executor` -> `robot1.executor`)."""
    return identity.replace("/", ".")


def _service(service: str, **more: tuple[str, ...]) -> Grant:
    """A service's own keys: its streams and errors, heartbeat, traces, token, endpoints."""
    own = keys.owned(service)
    publish = (own, keys.heartbeat(service), keys.trace(own))
    return Grant(
        service,
        publish=publish + more.pop("publish", ()),
        serve=(keys.service_rpc(service, "**"), *more.pop("serve", ())),
        tokens=(keys.alive(service),),
        **more,
    )


def _agent_reads(agent: str) -> tuple[str, ...]:
    """What every service of `agent` reads: its own agent's keys, the world's shared
    streams and those addressed to it, its group's claims and acks, who is alive."""
    return (
        keys.owned(agent),
        keys.CLOCK,
        keys.world_stream("info"),
        keys.EVENTS,
        keys.world_for_agent(agent),
        keys.scheduler_claims_all(),
        keys.epoch_ack("*", "scheduler"),
        keys.ALIVE_ALL,
    )


_WORLD_ASKS = (keys.world_rpc("info"), keys.world_rpc("clock"))


def agent_grants(agent: str, components: Iterable[str], group: str = "") -> list[Grant]:
    """The grants of one agent's services and of its performers and sensors.

    With `group` (its agent file's), its scheduler may ask any agent under that group
    (a rule's `ask`, docs/agents.md); never under `operator` or `sensors`, which are
    not an agent file's to claim.
    """
    out = []
    peers = group if group and group not in (OPERATOR_GROUP, SENSOR_GROUP) else ""
    for component in components:
        # Only its executor asks the world for its actions; only its scheduler, the group.
        act = (keys.world_act(agent),) if component == "executor" else ()
        ask = peers if component == "scheduler" else ""
        group_asks = (keys.agent_request("*", ask),) if ask else ()
        asks: tuple[str, ...] = (*_WORLD_ASKS, keys.owned(agent), *act, *group_asks)
        out.append(
            _service(
                keys.service_id(component, agent),
                read=_agent_reads(agent),
                query=asks,
                groups=(ask,) if ask else (),
            )
        )
    performer = keys.service_id(PERFORMER, agent)
    out.append(
        _service(
            performer,
            read=(
                keys.CLOCK,
                keys.world_for_agent(agent),
                keys.agent_stream(agent, "executor", "stop"),
                keys.epoch_ack(agent, "executor"),  # lockstep: its calls of an epoch are in
                keys.ALIVE_ALL,
            ),
            # A performer is the agent's body: it may carry an action out in a
            # simulated world (the agent's own actions only).
            query=(keys.agent_request(agent, SENSOR_GROUP), keys.world_act(agent), *_WORLD_ASKS),
            groups=(SENSOR_GROUP,),
        )
    )
    return out


def grants(
    agents: Sequence[tuple[str, Sequence[str]]], groups: Mapping[str, str] | None = None
) -> list[Grant]:
    """Return every identity of a run of `agents` (name, its components); `groups`: each
    agent's group (its agent file's), under which its scheduler may ask the others.

    The world alone writes world state, events and percepts; the monitor and the
    launcher read everything, and so does `viewer` (`cbdi view --live`), which writes
    nothing; `operator` (`cbdi ctl`) asks any agent under group `operator`, and reads who
    is alive, the world's public streams and desire events.
    """
    everything = (keys.ALL,)
    out = [
        _service(
            WORLD,
            # Performers' outcomes too: the run's trace folds them in (cbdi.robot).
            read=(
                keys.epoch_ack_all(),
                keys.owned(WORLD),
                keys.ALIVE_ALL,
                keys.agent_stream("*", PERFORMER, "outcomes"),
            ),
        ),
        _service(MONITOR, read=everything, query=_WORLD_ASKS),
        _service(
            LAUNCHER,
            read=everything,
            query=(*_WORLD_ASKS, keys.world_rpc("stats")),
        ),
        Grant(VIEWER, read=everything, query=_WORLD_ASKS),
        Grant(
            OPERATOR,
            read=(
                keys.ALIVE_ALL,
                *(keys.world_stream(s) for s in ("clock", "snapshot", "stats", "info", "events")),
                keys.agent_stream("*", "scheduler", "desires"),
            ),
            query=(
                keys.component_rpc("*", "scheduler", "state"),
                keys.agent_request("*", OPERATOR_GROUP),
                keys.component_rpc("*", "executor", "stop"),
            ),
            groups=(OPERATOR_GROUP,),
        ),
    ]
    for agent, components in agents:
        out += agent_grants(agent, components, (groups or {}).get(agent, ""))
    return out


# What a compose run has besides: `cbdi wait` (it reads how the run ends), and the
# router's own identity, with which it joins another host's router and carries all of
# its side's traffic.
COMPOSE_GRANTS = (
    _service("wait", read=(keys.ALL,), query=(keys.world_rpc("stats"),)),
    Grant(
        "router",
        publish=(keys.ALL,),
        read=(keys.ALL,),
        serve=(keys.ALL,),
        query=(keys.ALL,),
        tokens=(keys.ALL,),
    ),
)


def _adv(exprs: Iterable[str], tail: str) -> list[str]:
    return [keys.advanced(k, tail) for k in exprs]


def _rules(g: Grant) -> list[tuple[str, tuple[str, ...], str, list[str]]]:
    """(name, messages, flow, key expressions) of one grant's allow rules."""
    pub, read = list(g.publish), list(g.read)
    return [
        # Its publications, and its advanced publishers' tokens, caches and heartbeats.
        ("publish", _ALL, "ingress", pub + _adv(pub, "**")),
        ("publish-asked", ("query",), "egress", _adv(pub, "**")),
        # What it reads: subscriptions (and an advanced subscriber's token, heartbeat
        # subscription and cache queries), then what the router hands it.
        ("read", _SUBSCRIBE, "ingress", read + _adv(read, "**")),
        ("read-recover", ("query",), "ingress", _adv(read, "**")),
        ("read-token", ("liveliness_token",), "ingress", _adv(read, "sub/**")),
        ("read-get", (*_PUT, "liveliness_token"), "egress", read + _adv(read, "**")),
        ("read-reply", ("reply",), "egress", read + _adv(read, "**")),  # caches' replies
        ("serve", ("declare_queryable", "reply"), "ingress", list(g.serve)),
        ("serve-asked", ("query",), "egress", list(g.serve)),
        ("query", ("query",), "ingress", list(g.query)),
        ("query-reply", ("reply",), "egress", list(g.query)),
        ("token", ("liveliness_token",), "ingress", list(g.tokens)),
    ]


def acl_config(all_grants: Sequence[Grant], hub: str = "") -> dict[str, Any]:
    """Return the router's `access_control` configuration: deny by default, allow what
    each identity's grant says, to that identity's user name only.

    `hub`: the Zenoh id of the run's hub router, which other routers join (`cbdi
    compose --join`). Zenoh's user-password login proves the router that opens a link to
    the one that accepts it only, so the joining router knows the hub by its id: the hub
    gets the `router` grant. The id is a random one of the run's secrets, and the joiner
    lets in only sessions that logged in, so posing as the hub takes the run's secrets.

    Every authenticated identity is also told of declarations under `cbdi/**` (who
    subscribes, serves, is alive), so that publishers and queriers find their peers;
    that says which keys are in use, never what is on them.
    """
    rules: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    everyone = [g.user for g in all_grants]
    tell = [keys.ALL, keys.advanced(keys.ALL, "**")]
    rules.append(_rule("all-declarations", _DECLARATIONS, "egress", tell))
    # An advanced subscriber's recovery query names its own key expression (`cbdi/**/
    # @adv/*/<zid>/<eid>/**`) and reaches the one publisher whose cache it asks; what
    # that publisher answers, the reader's own rules let through or not.
    rules.append(_rule("all-recovery", ("query",), "egress", [keys.advanced(keys.ALL, "**")]))
    policies.append(
        {"id": "all", "rules": ["all-declarations", "all-recovery"], "subjects": everyone}
    )
    subjects = []
    for g in all_grants:
        ids = []
        for name, messages, flow, exprs in _rules(g):
            if exprs:
                rule_id = f"{g.user}:{name}"
                rules.append(_rule(rule_id, messages, flow, exprs))
                ids.append(rule_id)
        subjects.append({"id": g.user, "usernames": [g.user]})
        named = [g.user]
        if hub and g.identity == HUB_GRANT:
            subjects.append({"id": HUB_SUBJECT, "zids": [hub]})
            named.append(HUB_SUBJECT)
            policies[0]["subjects"].append(HUB_SUBJECT)  # told of declarations too
        policies.append({"id": g.user, "rules": ids, "subjects": named})
    # One subject per identity, the policy "all" naming them all.
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def _rule(rule_id: str, messages: Sequence[str], flow: str, exprs: Sequence[str]) -> dict[str, Any]:
    return {
        "id": rule_id,
        "messages": list(dict.fromkeys(messages)),
        "flows": [flow],
        "permission": "allow",
        "key_exprs": list(dict.fromkeys(exprs)),
    }
