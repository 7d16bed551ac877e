"""`cbdi router`: a Zenoh router in Python, so no separate zenohd binary is needed."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from cbdi.bus.zenoh_bus import DEFAULT_ENDPOINT
from cbdi.runtime import ServiceContext, ServiceSettings, load_config, run_service

__all__ = ["RouterSettings", "main"]


@dataclass(frozen=True)
class RouterSettings(ServiceSettings):
    """A router listens; it connects to nothing unless told to (to join other routers)."""

    mode: str = field(default="router", metadata={"help": "Zenoh mode (router)"})
    listen: tuple[str, ...] = field(
        default=(DEFAULT_ENDPOINT,), metadata={"help": "endpoints to listen on"}
    )
    connect: tuple[str, ...] = field(default=(), metadata={"help": "other routers to join"})


async def _router(ctx: ServiceContext) -> None:
    ctx.log.info("routing", listen=",".join(ctx.settings.listen))


def main(argv: Sequence[str] | None = None) -> int:
    """Run a Zenoh router until SIGTERM/SIGINT."""
    settings = load_config(
        RouterSettings,
        argv,
        prog="cbdi router",
        section="router",
        description="Run the Zenoh router every cbdi service connects to.",
    )
    return run_service(settings, "router", _router)
