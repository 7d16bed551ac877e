"""`cbdi compose SCENARIO`: a compose file running the scenario in containers, to its end.

The services are the ones `cbdi up` starts, with the same arguments (`plan_services`):
a router, the monitor recording to the host's `runs/`, the world (with `--member` for
every component of every agent: its start barrier is the readiness, not `depends_on`),
every agent's services, and `wait` (`cbdi wait`), which exits with the run's result:

    cbdi compose paper-7x7 --agents 2 -o run.yml
    docker-compose -f run.yml up --exit-code-from wait     # 0: the world done

A run can be split over several compose projects (hosts), each with its own router, the
routers joined: `--only` picks the agents (and `world`) a project runs, `--join` the
router to connect to, the run's hub (docs/containers.md). The projects share the run's
secrets (`--secrets`).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cbdi.errors import ConfigError
from cbdi.launcher.cli import scenario_arguments, scenario_from_args
from cbdi.launcher.scenario import AGENT_KINDS, Scenario, agent_groups
from cbdi.launcher.services import ServicePlan, agent_of, plan_services
from cbdi.runtime.fault import FAULT_ENV, parse_faults
from cbdi.runtime.life import LIFE_ENV
from cbdi.security import CREDENTIALS_ENV, Grant, RunSecrets, ensure_secrets, grants
from cbdi.security.policy import COMPOSE_GRANTS

__all__ = [
    "ComposeOptions",
    "compose_file",
    "compose_grants",
    "main",
    "secrets_beside",
    "write_secrets",
]

DOMAINS_IN_IMAGE = "/opt/cbdi/domains"  # where the Dockerfile puts domains/
RUNS_IN_CONTAINER = "/runs"
SECRETS_IN_CONTAINER = "/secrets"
WORLD_STATE = "/state/world.state"  # the world's state file (`cbdi-world --state`)
LIFE_FILE = "/state/life"  # a service's starts (`cbdi.runtime.life`)
WORLD_PART = "world"  # `--only world`: the world, the monitor and `wait`
# Podman as root gives containers nofile=1048576; where the host's hard limit is lower
# the container cannot start ("error setting rlimit"). A service needs far fewer.
ULIMITS = {"nofile": 4096, "nproc": 4096}


@dataclass(frozen=True)
class ComposeOptions:
    """How the compose file runs the scenario's services."""

    image: str = "${CBDI_IMAGE:-localhost/cbdi:latest}"
    port: int = 7447
    network: str = "bridge"  # or "host": every service on the host's loopback
    listen: str = ""  # the router's endpoint (default: all interfaces, or loopback with host)
    join: tuple[str, ...] = ()  # other routers ours connects to
    publish: bool = False  # publish the router's port on the host's loopback (bridge)
    only: tuple[str, ...] = ()  # agents (and `world`) this project runs; () for all
    runs: str = "./runs"  # the host directory the monitor records into
    record: str = ""  # the recording's file name in `runs` ("" : SCENARIO.mcap)
    wait_agents: float = 600.0  # the world's start barrier, in wall seconds at most
    timeout: float = 0.0  # `cbdi wait --timeout`
    # The run's secrets on the host (`cbdi compose` writes them), mounted read-only in
    # every container; "" : no security (docs/security.md).
    secrets: str = "./secrets"
    # Faults to inject (`--fault SERVICE:KIND@EPOCH`, `cbdi.runtime.fault`): each goes
    # into its service's environment; the container's life file keeps it to the first life.
    faults: tuple[str, ...] = ()


def compose_file(scenario: Scenario, opts: ComposeOptions, command: str = "") -> str:
    """Return the compose file (YAML) running `scenario` with `opts`."""
    host = opts.network == "host"
    listen = opts.listen or f"tcp/{'127.0.0.1' if host else '0.0.0.0'}:{opts.port}"
    connect = f"tcp/{'127.0.0.1' if host else 'router'}:{opts.port}"
    record = f"{RUNS_IN_CONTAINER}/{opts.record or scenario.name + '.mcap'}"
    plans = plan_services(scenario, listen, record, _in_image)
    wanted = _parts(scenario, opts.only)
    faults = _faults(opts.faults, [p.service for p in plans])
    services: dict[str, Any] = {}
    for plan in plans:
        part = agent_of(plan.service) or WORLD_PART
        if plan.service != "router" and part not in wanted:
            continue
        services[_name(plan.service)] = _service(plan, opts, connect, scenario)
        if plan.service in faults:
            services[_name(plan.service)]["environment"][FAULT_ENV] = faults[plan.service]
    if WORLD_PART in wanted:
        until = "done" if scenario.run.until == "done" else "time_limit"
        args = ("wait", "--until", until, "--timeout", str(opts.timeout))
        wait = ServicePlan("wait", "cbdi", "cbdi.cli", args)
        services["wait"] = _service(wait, opts, connect, scenario)
    header = [
        "# Generated; edit the scenario and generate it again:",
        f"#   {command or 'cbdi compose ' + scenario.name}",
        "# Run it (docs/containers.md):",
        "#   docker-compose -f FILE up --exit-code-from wait; docker-compose -f FILE down",
        "#   (to live through a crash: up -d; docker wait $(docker-compose -f FILE ps -q wait))",
        "#   (or podman-compose, or docker compose)",
    ]
    return "\n".join(header) + "\n" + _yaml({"services": services}) + "\n"


def _faults(entries: Sequence[str], services: Sequence[str]) -> dict[str, str]:
    """Return each faulted service's fault; the router counts no restarts (it has no
    volume of its own), so a fault of it would strike each of its lives: refused."""
    try:
        faults = parse_faults(entries)
    except ValueError as exc:
        raise ConfigError("--fault", ",".join(entries), str(exc)) from None
    allowed = [s for s in services if s != "router"]
    for fault in faults:
        if fault.service not in allowed:
            known = ", ".join(sorted(allowed))
            raise ConfigError(
                "--fault", str(fault), f"not a service a container run can fault ({known})"
            )
    return {f.service: str(f) for f in faults}


def _parts(scenario: Scenario, only: tuple[str, ...]) -> set[str]:
    names = {a.name for a in scenario.agents}
    if not only:
        return names | {WORLD_PART}
    unknown = [p for p in only if p not in names | {WORLD_PART}]
    if unknown:
        known = ", ".join([WORLD_PART, *sorted(names)])
        raise ConfigError("--only", ",".join(unknown), f"expected some of {known}")
    return set(only)


def _service(
    plan: ServicePlan, opts: ComposeOptions, connect: str, scenario: Scenario
) -> dict[str, Any]:
    service: dict[str, Any] = {"image": opts.image, "command": [plan.script, *plan.args]}
    env = {"CBDI_LOG_FORMAT": "kv", "PYTHONHASHSEED": "0"}
    if plan.service != "router":
        # Containers start together: wait for the router (and the credentials it makes
        # when missing), do not fail for their absence.
        env |= {"CBDI_CONNECT": connect, "CBDI_CONNECT_TIMEOUT": "120"}
    if opts.secrets:
        env |= _secured(plan.service, scenario, hub=not opts.join)
        # The router makes the run's secrets when the directory lacks them (a fresh clone)
        mode = "" if plan.service == "router" else ":ro"
        service["volumes"] = [f"{opts.secrets}:{SECRETS_IN_CONTAINER}{mode}"]
    service["environment"] = env
    if plan.service == "router" and opts.join:
        service["command"] += [a for j in opts.join for a in ("--connect", j)]
    if plan.service not in ("router", "wait"):
        # A volume of the container's own (kept over its restarts, new for a new
        # container): the service counts its starts there, so that one restarted by the
        # policy knows it was (`cbdi.runtime.life`: the monitor goes on in a new part,
        # the planner numbers its plans apart), and the world keeps its state there.
        service["environment"][LIFE_ENV] = LIFE_FILE
        service["volumes"] = [*service.get("volumes", []), str(Path(LIFE_FILE).parent)]
    if plan.service == "world":
        service["command"] += ["--wait-agents", str(opts.wait_agents)]
        # Restarted after a crash, it goes on where it was; the file goes at the end.
        service["environment"] |= {"CBDI_STATE": WORLD_STATE, "CBDI_RESUME": "if-found"}
    if opts.network == "host":
        service["network_mode"] = "host"
    elif plan.service == "router" and opts.publish:
        service["ports"] = [f"127.0.0.1:{opts.port}:{opts.port}"]
    if plan.service == "monitor":
        service["volumes"] = [f"{opts.runs}:{RUNS_IN_CONTAINER}", *service.get("volumes", [])]
        service["stop_grace_period"] = "30s"  # it finishes the MCAP file on SIGTERM
    else:
        service["stop_grace_period"] = "10s"
    if plan.service != "router":  # start order only: the world's barrier is the readiness
        # The monitor first, so that it records from epoch -1.
        service["depends_on"] = ["router", "monitor"] if plan.service == "world" else ["router"]
    service["restart"] = "no" if plan.service == "wait" else "on-failure"
    service["ulimits"] = dict(ULIMITS)
    return service


def _secured(service: str, scenario: Scenario, hub: bool) -> dict[str, str]:
    """The environment naming a service's secrets in its container: its credentials (the
    router's: to join another router), and the router's user list and rules; a router
    that joins none is the run's hub, with the hub's Zenoh id, by which the routers
    that join it know it (`cbdi.security.policy.acl_config`). The router makes the
    secrets of the run's agents when they are missing (`cbdi router --secrets-dir`)."""
    inside = RunSecrets(Path(SECRETS_IN_CONTAINER))
    env = {CREDENTIALS_ENV: str(inside.credentials(service))}
    if service == "router":
        env |= {"CBDI_USERS": str(inside.users), "CBDI_ACL": str(inside.acl)}
        if hub:
            env["CBDI_ZENOH_CONFIG"] = str(inside.hub)
        groups = agent_groups(scenario)
        agents = ",".join(
            f"{a.name}:{a.kind}" + (f":{groups[a.name]}" if a.name in groups else "")
            for a in scenario.agents
        )
        env |= {"CBDI_SECRETS_DIR": SECRETS_IN_CONTAINER, "CBDI_SECRETS_AGENTS": agents}
    return env


def compose_grants(
    agents: Sequence[tuple[str, str]], groups: Mapping[str, str] | None = None
) -> list[Grant]:
    """Return every identity of a compose run of `agents` (name, kind): `cbdi up`'s,
    `wait`'s and the routers'; `groups` as `grants` takes them."""
    components = [(name, AGENT_KINDS[kind]) for name, kind in agents]
    return [*grants(components, groups), *COMPOSE_GRANTS]


def write_secrets(scenario: Scenario, where: Path) -> bool:
    """Write the run's secrets in `where`, unless it holds every identity's already (the
    projects of a run split over hosts share one set); return whether it wrote them."""
    agents = [(a.name, a.kind) for a in scenario.agents]
    return ensure_secrets(where, compose_grants(agents, agent_groups(scenario)))


def secrets_beside(secrets: str, output: str) -> Path:
    """Return where the host's secrets go: a relative `--secrets` is one from the compose
    file's folder, as Compose resolves the file's volumes (from the working directory
    when the file goes to stdout)."""
    where = Path(secrets)
    if where.is_absolute() or output == "-":
        return where
    return Path(output).parent / where


def _name(service: str) -> str:
    """Compose service names cannot hold '/': robot1/planner is robot1-planner."""
    return service.replace("/", "-")


def _in_image(path: Path) -> str:
    """Return where `path` is in the image: every shipped file is under domains/."""
    for root in _domain_roots():
        try:
            rel = path.resolve().relative_to(root)
        except ValueError:
            continue
        return f"{DOMAINS_IN_IMAGE}/{rel.as_posix()}"
    raise ConfigError(
        str(path), "path", "not under domains/: the image carries only domains/ (put it there)"
    )


def _domain_roots() -> list[Path]:
    roots = [Path.cwd() / "domains", Path(__file__).resolve().parents[4] / "domains"]
    if os.environ.get("CBDI_DOMAINS"):
        roots.insert(0, Path(os.environ["CBDI_DOMAINS"]))
    return [r.resolve() for r in roots if r.is_dir()]


_PLAIN = re.compile(r"^[A-Za-z0-9_./${}:@-][A-Za-z0-9_./${}:@ -]*$")


def _scalar(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return str(value)
    text = str(value)
    special = text in ("no", "yes", "true", "false", "null", "on", "off", "~", "")
    numeric = re.fullmatch(r"[-+0-9.eE]+", text) is not None
    if special or numeric or not _PLAIN.match(text) or ": " in text or text.endswith(":"):
        return json.dumps(text)  # a JSON string is a YAML string
    return text


def _yaml(value: object, indent: int = 0) -> str:
    """Emit the small subset of YAML a compose file needs: maps, lists, scalars."""
    pad = "  " * indent
    if isinstance(value, dict):
        lines = []
        for key, item in value.items():
            if isinstance(item, list) and not any(isinstance(v, dict | list) for v in item):
                lines.append(f"{pad}{key}: {_yaml(item)}")
            elif isinstance(item, dict | list) and item:
                lines.append(f"{pad}{key}:\n{_yaml(item, indent + 1)}")
            else:
                lines.append(f"{pad}{key}: {_scalar(item) if item != [] else '[]'}")
        return "\n".join(lines)
    if isinstance(value, list):
        if all(not isinstance(v, dict | list) for v in value):
            return f"{pad}[{', '.join(json.dumps(str(v)) for v in value)}]"
        return "\n".join(f"{pad}- {_yaml(v, 0)}" for v in value)
    return pad + _scalar(value)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cbdi compose",
        description="Write a compose file that runs the scenario in containers (one image, "
        "localhost/cbdi: `make image`) and ends with the run's result: `docker-compose up "
        "--exit-code-from wait` exits 0 only when the run ended as asked.",
    )
    scenario_arguments(p)
    p.add_argument("-o", "--output", default="-", help="compose file to write (- : stdout)")
    p.add_argument("--image", default=ComposeOptions.image, help="the cbdi image")
    p.add_argument("--port", type=int, default=7447, help="the router's port")
    p.add_argument(
        "--network",
        choices=("bridge", "host"),
        default="bridge",
        help="bridge: a network of the project; host: every service on the host's loopback",
    )
    p.add_argument("--listen", default="", help="the router's endpoint (default from --network)")
    p.add_argument("--join", action="append", default=[], help="another router to connect to")
    p.add_argument(
        "--publish", action="store_true", help="publish the router's port on 127.0.0.1 (bridge)"
    )
    p.add_argument(
        "--only",
        default="",
        help="comma-separated agents (and 'world': world, monitor, wait) this project runs",
    )
    p.add_argument("--runs", default="./runs", help="host directory of the recording")
    p.add_argument("--record", default="", help="the recording's file name (default SCENARIO.mcap)")
    p.add_argument(
        "--wait-agents", type=float, default=600.0, help="the world's start barrier, seconds"
    )
    p.add_argument("--timeout", type=float, default=0.0, help="cbdi wait: wall seconds at most")
    p.add_argument(
        "--secrets",
        default=ComposeOptions.secrets,
        help="host directory of the run's credentials, written now (mode 0600) unless it "
        "holds them already; relative: from the compose file's folder, as Compose reads "
        "it; mounted read-only in every container (docs/security.md)",
    )
    p.add_argument(
        "--secure",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="authenticated services, access control at the router (default)",
    )
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="SERVICE:KIND@EPOCH",
        help="inject a fault: SERVICE (world, robot1/planner, ...) is killed (kill) or "
        "frozen (stop) as the world's epoch EPOCH reaches it, in its container's first "
        "life only; repeatable (docs/faults.md)",
    )
    return p


def _command(args: argparse.Namespace) -> str:
    """Return the command line that generates the same file (for the file's header)."""
    parts = ["cbdi compose", args.scenario]
    for action in _parser()._actions:
        value = getattr(args, action.dest, None)
        if not action.option_strings or action.dest in ("help", "output"):
            continue
        if value == action.default or value is None:
            continue
        flag = action.option_strings[0]
        if isinstance(value, bool):  # --lockstep/--no-lockstep, or a store_true flag
            parts.append(flag if value else action.option_strings[-1])
        elif isinstance(value, list):
            parts.extend(f"{flag} {v}" for v in value)
        else:
            parts.append(f"{flag} {value}")
    return " ".join(parts)


def main(argv: Sequence[str] | None = None) -> int:
    """Write the compose file; exit 2 on a bad scenario or option."""
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    opts = ComposeOptions(
        image=args.image,
        port=args.port,
        network=args.network,
        listen=args.listen,
        join=tuple(args.join),
        publish=args.publish,
        only=tuple(p for p in args.only.split(",") if p),
        runs=args.runs,
        record=args.record,
        wait_agents=args.wait_agents,
        timeout=args.timeout,
        secrets=args.secrets if args.secure else "",
        faults=tuple(args.fault),
    )
    try:
        scenario = scenario_from_args(args)
        text = compose_file(scenario, opts, _command(args))
    except ConfigError as exc:
        print(f"cbdi compose: {exc}", file=sys.stderr)
        return 2
    where = secrets_beside(opts.secrets, args.output)
    if opts.secrets and write_secrets(scenario, where):
        print(f"cbdi compose: wrote the run's credentials in {where}", file=sys.stderr)
    if args.output == "-":
        sys.stdout.write(text)
    else:
        Path(args.output).write_text(text, encoding="utf-8")
    return 0
