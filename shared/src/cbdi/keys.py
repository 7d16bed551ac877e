"""Build every Zenoh key expression of cbdi. No key string is spelled anywhere else.

Layout (documented in docs/protocol.md):

- per agent: `cbdi/<agent>/<component>/<stream>`, e.g. `cbdi/robot1/executor/ack`
- shared world: `cbdi/world/<stream>` and per-agent world streams
  `cbdi/world/<stream>/<agent>` (percepts, outcomes)
- requests (queryables): `cbdi/world/rpc/<name>`, `cbdi/<agent>/<component>/rpc/<name>`;
  scoped by who may ask (docs/security.md): an agent's actions `cbdi/world/rpc/act/<agent>`,
  a multi-agent request under a group `cbdi/<agent>/scheduler/rpc/request/<group>`
- error streams: `cbdi/world/errors`, `cbdi/<agent>/<component>/errors`
- liveliness tokens: `cbdi/alive/<service-id>` where the service id is `world`,
  `monitor`, or `<agent>/<component>`
- heartbeats: `cbdi/heartbeat/<service-id>` (each service's event loop, wall clock)
- request tracing for recorders: `cbdi/trace/<request key>/request` and `.../reply`
- every key of a service id or agent: `cbdi/<name>/**`; of the run: `cbdi/**`; Zenoh's
  advanced publishers and subscribers use `<key expression>/@adv/...` beside them
- the launcher's word for recorders: `cbdi/launcher/<stream>` (`run`: what it started)
"""

from __future__ import annotations

import functools
import re

__all__ = [
    "ALIVE_ALL",
    "ALL",
    "CLOCK",
    "EVENTS",
    "HEARTBEAT_ALL",
    "ROOT",
    "SNAPSHOT",
    "STATS",
    "WORLD",
    "advanced",
    "agent_ack",
    "agent_ack_all",
    "agent_request",
    "agent_stream",
    "alive",
    "component_rpc",
    "describe",
    "epoch_ack",
    "epoch_ack_all",
    "errors",
    "executor_arrested",
    "executor_status",
    "heartbeat",
    "is_ack",
    "is_heartbeat",
    "is_request_to",
    "is_stream",
    "launcher_stream",
    "matches",
    "member",
    "monitor_stream",
    "owned",
    "planner_forecasts",
    "planner_plans",
    "planner_requests",
    "planner_rounds",
    "planner_status",
    "request_group",
    "scheduler_arrest",
    "scheduler_beliefs",
    "scheduler_claims",
    "scheduler_claims_all",
    "scheduler_desires",
    "scheduler_plans",
    "service_id",
    "service_of_alive",
    "service_rpc",
    "trace",
    "trace_reply",
    "trace_request",
    "traced_request",
    "validate_name",
    "world_act",
    "world_for_agent",
    "world_outcomes",
    "world_percepts",
    "world_rpc",
    "world_rpc_scope",
    "world_stream",
]

ROOT = "cbdi"
WORLD = "world"
ALL = f"{ROOT}/**"  # every key of cbdi (what a recorder hears)
ALIVE_ALL = f"{ROOT}/alive/**"
HEARTBEAT_ALL = f"{ROOT}/heartbeat/**"

# World streams (published by the world service).
CLOCK = f"{ROOT}/{WORLD}/clock"
SNAPSHOT = f"{ROOT}/{WORLD}/snapshot"
STATS = f"{ROOT}/{WORLD}/stats"
EVENTS = f"{ROOT}/{WORLD}/events"

# Names that may not be used as agents because they are shared chunks of the layout.
_RESERVED = {WORLD, "alive", "heartbeat", "trace", "monitor", "launcher"}
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_\-]{0,62}$")


def validate_name(name: str, what: str = "agent") -> str:
    """Return `name` if it can be one key chunk, else raise ValueError saying why."""
    if not _NAME.match(name):
        raise ValueError(
            f"{what} name {name!r} must start with a letter and hold only letters, digits,"
            " '_' or '-' (at most 63 characters)"
        )
    if what == "agent" and name in _RESERVED:
        raise ValueError(f"{what} name {name!r} is reserved by the key layout")
    return name


def world_stream(stream: str) -> str:
    """Return the key of a shared world stream (`clock`, `snapshot`, `stats`, `events`)."""
    return f"{ROOT}/{WORLD}/{stream}"


def world_percepts(agent: str) -> str:
    """Return the key on which the world publishes `agent`'s percepts (`*` for all)."""
    return f"{ROOT}/{WORLD}/percepts/{agent}"


def world_outcomes(agent: str) -> str:
    """Return the key on which the world reports `agent`'s action outcomes (`*` for all)."""
    return f"{ROOT}/{WORLD}/outcomes/{agent}"


def world_for_agent(agent: str) -> str:
    """Return the key expression matching every world stream addressed to `agent`."""
    return f"{ROOT}/{WORLD}/*/{agent}"


def world_rpc(name: str) -> str:
    """Return the key of a world request endpoint (`act`, `stats`, `info`)."""
    return f"{ROOT}/{WORLD}/rpc/{name}"


def world_act(agent: str) -> str:
    """Return the key on which `agent` asks the world for its actions (`*` for all).

    One key per agent, so that the router can let only that agent's executor ask on it;
    the world checks that a request's agent is the key's (`world_rpc_scope`).
    """
    return f"{world_rpc('act')}/{agent}"


def world_rpc_scope(key: str, name: str) -> str:
    """Return the chunk after `cbdi/world/rpc/<name>/` in `key` ('' when there is none)."""
    prefix = world_rpc(name) + "/"
    return key[len(prefix) :] if key.startswith(prefix) else ""


def agent_request(agent: str, group: str) -> str:
    """Return the key on which one asks `agent`'s scheduler something under `group`.

    The group is a key chunk, so that the router lets only identities of that group ask
    on it (docs/security.md); the scheduler takes the group from the key.
    """
    return f"{component_rpc(agent, 'scheduler', 'request')}/{group}"


def request_group(key: str) -> str:
    """Return the group chunk of an `agent_request` key ('' for the bare endpoint)."""
    parts = key.split("/")
    if len(parts) == 6 and parts[0] == ROOT and parts[2:5] == ["scheduler", "rpc", "request"]:
        return parts[5]
    return ""


def owned(name: str) -> str:
    """Return the key expression of every key of a service id or an agent: `cbdi/<name>/**`.

    A service's (`world`, `robot1/executor`): its streams, errors and request endpoints;
    an agent's (`robot1`): those of all its services.
    """
    return f"{ROOT}/{name}/**"


def service_rpc(service: str, name: str) -> str:
    """Return the key of a request endpoint of a service id (`**`: all its endpoints)."""
    return f"{ROOT}/{service}/rpc/{name}"


def is_request_to(key: str, component: str) -> bool:
    """Tell whether `key` is a request endpoint of an agent's `component` (`component_rpc`)."""
    parts = key.split("/")
    return len(parts) == 5 and parts[0] == ROOT and parts[2] == component and parts[3] == "rpc"


def advanced(expr: str, tail: str) -> str:
    """Return the key expression of Zenoh's advanced pub/sub keys of `expr` (`@adv/<tail>`).

    An advanced publisher's cache and liveliness token and an advanced subscriber's
    recovery queries live under these; access rules must name them beside `expr`.
    """
    return f"{expr}/@adv/{tail}"


def agent_stream(agent: str, component: str, stream: str) -> str:
    """Return `cbdi/<agent>/<component>/<stream>`."""
    return f"{ROOT}/{agent}/{component}/{stream}"


def component_rpc(agent: str, component: str, name: str) -> str:
    """Return the key of a request endpoint of an agent's component."""
    return f"{ROOT}/{agent}/{component}/rpc/{name}"


def scheduler_plans(agent: str) -> str:
    """Return the key on which the scheduler passes plans to its executor."""
    return agent_stream(agent, "scheduler", "plans")


def scheduler_arrest(agent: str) -> str:
    """Return the key on which the scheduler asks its executor for an early arrest."""
    return agent_stream(agent, "scheduler", "arrest")


def scheduler_beliefs(agent: str) -> str:
    """Return the key on which the scheduler publishes the agent's beliefs."""
    return agent_stream(agent, "scheduler", "beliefs")


def planner_requests(agent: str) -> str:
    """Return the key on which the scheduler asks its planner to start, revise, cancel."""
    return agent_stream(agent, "scheduler", "search")


def planner_plans(agent: str) -> str:
    """Return the key on which the planner publishes partial plans."""
    return agent_stream(agent, "planner", "plans")


def planner_status(agent: str) -> str:
    """Return the key on which the planner reports its search status."""
    return agent_stream(agent, "planner", "status")


def planner_rounds(agent: str) -> str:
    """Return the key on which the planner reports each search round's statistics."""
    return agent_stream(agent, "planner", "rounds")


def planner_forecasts(agent: str) -> str:
    """Return the key on which the planner reports its failure forecasts."""
    return agent_stream(agent, "planner", "forecasts")


def scheduler_desires(agent: str) -> str:
    """Return the key on which the scheduler reports desire events (activated, dropped)."""
    return agent_stream(agent, "scheduler", "desires")


def scheduler_claims(agent: str) -> str:
    """Return the key on which the scheduler announces its claims to its group."""
    return agent_stream(agent, "scheduler", "claims")


def scheduler_claims_all() -> str:
    """Return the key expression matching every agent's claims."""
    return agent_stream("*", "scheduler", "claims")


def executor_status(agent: str) -> str:
    """Return the key on which the executor reports every plan step's status."""
    return agent_stream(agent, "executor", "status")


def executor_arrested(agent: str) -> str:
    """Return the key on which the executor reports that it stopped (early arrest)."""
    return agent_stream(agent, "executor", "arrested")


def is_stream(key: str, component: str, stream: str) -> bool:
    """Tell whether `key` is some agent's `component` `stream` (`agent_stream`)."""
    return key.endswith(f"/{component}/{stream}")


def is_ack(key: str) -> bool:
    """Tell whether `key` is an epoch ack's, of any agent and component (`epoch_ack`)."""
    return key.endswith("/ack")


def agent_ack(agent: str) -> str:
    """Return the key on which `agent`'s executor acknowledges epochs (lockstep)."""
    return agent_stream(agent, "executor", "ack")


def agent_ack_all() -> str:
    """Return the key expression matching every agent's epoch acknowledgements."""
    return agent_stream("*", "executor", "ack")


def epoch_ack(agent: str, component: str) -> str:
    """Return the key on which one component of `agent` acknowledges epochs (lockstep)."""
    return agent_stream(agent, component, "ack")


def epoch_ack_all(agent: str = "*") -> str:
    """Return the key expression matching every component's acks (of one agent or all)."""
    return agent_stream(agent, "*", "ack")


def member(agent: str, component: str) -> str:
    """Return the lockstep member name `agent/component` (the service id)."""
    return service_id(component, agent)


def monitor_stream(stream: str) -> str:
    """Return the key of a monitor stream (`health`)."""
    return f"{ROOT}/monitor/{stream}"


def launcher_stream(stream: str) -> str:
    """Return the key of a launcher stream (`run`: the services it started, and how)."""
    return f"{ROOT}/launcher/{stream}"


def service_id(component: str, agent: str | None = None) -> str:
    """Return the id of a service: `world`, `monitor`, or `<agent>/<component>`."""
    return f"{agent}/{component}" if agent else component


def alive(service: str) -> str:
    """Return the liveliness token key of a service id."""
    return f"{ROOT}/alive/{service}"


def heartbeat(service: str) -> str:
    """Return the key on which a service id sends its heartbeats."""
    return f"{ROOT}/heartbeat/{service}"


def is_heartbeat(key: str) -> bool:
    """Return whether `key` is a heartbeat's (wall-clock: never part of a lockstep epoch)."""
    return key.startswith(f"{ROOT}/heartbeat/")


def service_of_alive(key: str) -> str:
    """Return the service id of a liveliness token key (inverse of `alive`)."""
    prefix = f"{ROOT}/alive/"
    return key[len(prefix) :] if key.startswith(prefix) else key


def errors(service: str) -> str:
    """Return the error stream of a service id (`world` or `<agent>/<component>`)."""
    return f"{ROOT}/{service}/errors"


def describe(key: str) -> dict[str, str]:
    """Name the parts of a concrete key: agent, component, stream (empty when shared).

    `cbdi/robot1/planner/plans` -> agent robot1, component planner, stream plans;
    `cbdi/world/percepts/robot1` -> agent robot1, component world, stream percepts;
    `cbdi/alive/robot1/executor` -> agent robot1, component executor, stream alive.
    """
    parts = key.split("/")
    if len(parts) < 2 or parts[0] != ROOT:
        return {"agent": "", "component": "", "stream": key}
    head, rest = parts[1], parts[2:]
    if head == WORLD:
        agent = rest[1] if len(rest) == 2 and rest[0] in ("percepts", "outcomes") else ""
        return {"agent": agent, "component": WORLD, "stream": "/".join(rest)}
    if head in ("alive", "heartbeat"):
        if len(rest) == 2:
            return {"agent": rest[0], "component": rest[1], "stream": head}
        return {"agent": "", "component": "/".join(rest), "stream": head}
    if head in ("trace", "monitor", "launcher"):
        return {"agent": "", "component": head, "stream": "/".join(rest)}
    return {"agent": head, "component": rest[0] if rest else "", "stream": "/".join(rest[1:])}


@functools.lru_cache(maxsize=4096)
def matches(expr: str, key: str) -> bool:
    """Tell whether the key expression `expr` matches `key`, by Zenoh's own rules.

    The one key matcher: the memory bus delivers by it and the epoch gate counts by it,
    so both hear what a subscriber on Zenoh hears. Raise ValueError for an expression
    or key Zenoh refuses (an empty chunk, a `*` inside a chunk). Remembered: the same
    few pairs come again every epoch.
    """
    import zenoh  # here, not at the top: a command that opens no session does not load it

    try:
        return bool(zenoh.KeyExpr(expr).intersects(zenoh.KeyExpr(key)))
    except zenoh.ZError as exc:
        raise ValueError(f"not a Zenoh key expression: {expr!r} or {key!r} ({exc})") from exc


def trace(key: str) -> str:
    """Return the trace key on which the request helper mirrors requests and replies."""
    return f"{ROOT}/trace/{key.removeprefix(ROOT + '/')}"


def trace_request(key: str) -> str:
    """Return the key on which a request asked on `key` is mirrored for recorders."""
    return f"{trace(key)}/request"


def trace_reply(key: str) -> str:
    """Return the key on which the reply to a request asked on `key` is mirrored."""
    return f"{trace(key)}/reply"


def traced_request(key: str) -> str:
    """Return the key asked on whose request `key` mirrors (inverse of `trace_request`).

    '' when `key` mirrors no request.
    """
    prefix, suffix = f"{ROOT}/trace/", "/request"
    if key.startswith(prefix) and key.endswith(suffix) and len(key) > len(prefix + suffix):
        return f"{ROOT}/{key[len(prefix) : -len(suffix)]}"
    return ""
