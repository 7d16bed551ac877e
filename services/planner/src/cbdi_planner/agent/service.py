"""The planner service of one agent: online (continual planning, `online_service`) or
offline (plan, then act; the paper's baseline, `offline_service`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from cbdi.agentfile import RawAgentFile
from cbdi.bus import sequenced_inputs
from cbdi.lockstep import announce_ready
from cbdi.runtime import ServiceContext, ServiceSettings
from cbdi.runtime.service import ServiceMain
from cbdi_planner.agent.continual import ContinualPlanner
from cbdi_planner.agent.epochs import INPUTS, Epochs
from cbdi_planner.agent.offline_service import OfflinePlannerService
from cbdi_planner.agent.online_service import OnlinePlannerService
from cbdi_planner.agent.transient import Transients
from cbdi_planner.pddl.ast import Domain

__all__ = ["OfflinePlannerService", "OnlinePlannerService", "PlannerSettings", "planner_main"]


@dataclass(frozen=True)
class PlannerSettings(ServiceSettings):
    """Settings of `cbdi-planner serve`."""

    agent: str = field(default="robot1", metadata={"help": "the agent this planner serves"})
    restart: int = field(
        default=0,
        metadata={
            "help": "restarts so far (cbdi up sets CBDI_RESTART): above 0 its plans are "
            "numbered apart from its predecessor's (robot1-plan-r1-1)"
        },
    )
    agent_file: str = field(default="", metadata={"help": "the agent file (TOML)"})
    backend: str = field(default="", metadata={"help": "cbdi or kairos (default: agent file)"})
    time_grid: float = field(default=1.0, metadata={"help": "snap step starts to this grid"})
    planning: str = field(default="", metadata={"help": "online or offline (default: agent file)"})
    improve: bool = field(default=True, metadata={"help": "online: look for improved plans"})
    planning_speed: float = field(
        default=0.0,
        metadata={"help": "virtual time: expansions per simulated second (0: agent file's)"},
    )
    ack_timeout: float = field(
        default=120.0, metadata={"help": "lockstep: seconds to wait for the scheduler's epoch"}
    )


def planner_main(settings: PlannerSettings, domain: Domain, raw: RawAgentFile) -> ServiceMain:
    """Return the service body of one agent's planner (online or offline)."""

    async def body(ctx: ServiceContext) -> None:
        backend = settings.backend or raw.planning.backend
        mode = settings.planning or raw.planning.mode
        if mode == "online":
            core = ContinualPlanner(
                settings.agent,
                domain,
                raw.planning,
                settings.time_grid,
                log=ctx.log.info,
                improve=settings.improve,
                transients=Transients(raw.transient),
                life=settings.restart,
            )
            online = OnlinePlannerService(ctx, core, settings.planning_speed, settings.ack_timeout)
            stream = sequenced_inputs(ctx.bus, online.input_keys(), INPUTS, ctx)
            ctx.start(online.inputs(stream), name="planner")
            ctx.start(online.rounds(), name="rounds")
            service: Epochs = online
        else:
            service = OfflinePlannerService(
                ctx,
                settings.agent,
                domain,
                raw,
                backend,
                settings.time_grid,
                settings.planning_speed,
                settings.ack_timeout,
                life=settings.restart,
            )
            stream = sequenced_inputs(ctx.bus, service.input_keys(), INPUTS, ctx)
            ctx.start(service.inputs(stream), name="planner")
        ready = announce_ready(
            ctx.bus, settings.agent, "planner", service.lockstep.decided, lockstep=service.lockstep
        )
        ctx.start(ready, name="ready")

    return body
