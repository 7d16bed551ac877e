"""The processes of a `cbdi up` run: one per service, or one per BDI agent
(`run_specs`), each with its arguments, environment and credentials."""

from __future__ import annotations

from cbdi import keys
from cbdi.launcher.process import ProcessSpec, console_script
from cbdi.launcher.scenario import Scenario
from cbdi.launcher.services import ServicePlan, agent_of, plan_services
from cbdi.runtime.fault import FAULT_ENV
from cbdi.runtime.host import SEPARATOR as HOST_SEPARATOR
from cbdi.security import CREDENTIALS_ENV, RunSecrets

__all__ = ["WORLD_LINGER", "run_specs"]

# After the run ended the world still answers (the launcher asks for its statistics)
# this long at most, should the launcher not stop it (wall seconds). In the environment,
# not the arguments: those are the ones `cbdi compose` gives, whose world stays.
WORLD_LINGER = 30.0


def run_specs(
    scenario: Scenario,
    endpoint: str,
    record: str = "",
    heartbeat: float = 0.5,
    agent_process: bool = False,
    state: str = "",
    secrets: RunSecrets | None = None,
    faults: str = "",
) -> list[ProcessSpec]:
    """Return the run's processes: one per service, or with `agent_process` one per BDI
    agent (`robot1/agent`, running its components with `cbdi agent`). The world saves
    its state to the file `state` (none if ''). With `secrets`, each service logs in
    with its own credentials and the router checks them. Every process gets the
    `faults` to inject (`CBDI_FAULT`); each service takes the ones naming it."""
    common = {"CBDI_HEARTBEAT": str(heartbeat), **({FAULT_ENV: faults} if faults else {})}
    # A fixed hash seed: no decision may hang on the order of a set of strings.
    env = {"CBDI_CONNECT": endpoint, "PYTHONHASHSEED": "0", **common}
    world = {**env, "CBDI_LINGER": str(WORLD_LINGER), **({"CBDI_STATE": state} if state else {})}
    router = dict(common)
    if secrets is not None:
        router |= {"CBDI_USERS": str(secrets.users), "CBDI_ACL": str(secrets.acl)}
    own = {"router": router, "world": world}
    bdi = {a.name for a in scenario.agents if a.kind == "bdi"} if agent_process else set()
    units: dict[str, list[ServicePlan]] = {}  # process id -> the services it runs, in order
    for p in plan_services(scenario, endpoint, record):
        agent = agent_of(p.service)
        process = keys.service_id("agent", agent) if agent in bdi else p.service
        units.setdefault(process, []).append(p)
    specs = []
    for service, plans in units.items():
        if len(plans) == 1 and plans[0].service == service:
            program = console_script(plans[0].script, plans[0].module)
            penv = own.get(service, env)
            if secrets is not None and service != "router":
                penv = {**penv, CREDENTIALS_ENV: str(secrets.credentials(service))}
            specs.append(ProcessSpec.of(service, program, plans[0].args, penv))
        else:
            specs.append(_host_spec(service, plans, env, secrets))
    return specs


def _host_spec(
    service: str, plans: list[ServicePlan], env: dict[str, str], secrets: RunSecrets | None
) -> ProcessSpec:
    """Return the process running `plans` with `cbdi agent` (sections split by `--`),
    each section with its own credentials."""
    args: list[str] = ["agent"]
    for plan in plans:
        if len(args) > 1:
            args.append(HOST_SEPARATOR)
        args += [plan.service.rsplit("/", 1)[-1], *plan.args]
        if secrets is not None:
            args += ["--credentials", str(secrets.credentials(plan.service))]
    program = console_script("cbdi", "cbdi.cli")
    return ProcessSpec.of(service, program, args, env, [p.service for p in plans])
