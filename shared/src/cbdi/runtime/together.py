"""Run several services in one process, each its own asyncio service on its own bus.

Every service keeps what `run_service` gives it (a context, its TaskGroup, liveliness
once ready, the error stream) but shares the event loop with the others, on endpoints of
one bus network: the in-memory one (`MemoryNetwork`) for tests of every service shell
together, deterministic and without a network. `cbdi.lockstep` makes the run the same
as with one process per service.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence

from cbdi.bus.memory import MemoryNetwork
from cbdi.runtime.log import Log
from cbdi.runtime.service import Hosted as TogetherService  # one service to run
from cbdi.runtime.service import ServiceContext, ServiceMain, _supervise

__all__ = ["Together", "TogetherService"]


class Together:
    """Services sharing one event loop and one in-memory network until `stop()`."""

    def __init__(
        self,
        services: Sequence[TogetherService],
        network: MemoryNetwork,
        log_level: str = "warning",
    ) -> None:
        self.network = network
        self.contexts = [
            ServiceContext(s.service, network.bus(), Log(s.service, level=log_level), s.settings)
            for s in services
        ]
        self.mains = [s.main for s in services]

    async def run(self) -> dict[str, int]:
        """Run every service until all are stopped; return their exit codes."""
        async with asyncio.TaskGroup() as tg:
            for ctx, main in zip(self.contexts, self.mains, strict=True):
                tg.create_task(self._one(ctx, main), name=ctx.service)
        return {ctx.service: ctx.exit_code for ctx in self.contexts}

    async def _one(self, ctx: ServiceContext, main: ServiceMain) -> None:
        try:
            await _supervise(ctx, main)
        finally:
            await ctx._flush_reports()
            await ctx.bus.close()

    def stop(self) -> None:
        """Ask every service to end."""
        for ctx in self.contexts:
            ctx.stop()
