"""Join a run's bus as one of its identities, from a process `cbdi up` did not start.

A robot's own process (its performers and sensors, `docs/tutorial/robot.py`) or an
operator's tool may start before the run: `open_as` waits for the router and for the
run's credentials of that identity (`$CBDI_CREDENTIALS`, or the local run on the
endpoint's port, `cbdi.security.discover`), and joins without credentials when the
run turns out to have no security (`cbdi up --no-secure`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from cbdi.bus.zenoh_bus import BusConfig, ZenohBus, open_bus
from cbdi.clock import WallClock
from cbdi.errors import CbdiError, ConfigError
from cbdi.security.secrets import CREDENTIALS_ENV, discover, read_credentials

__all__ = ["config_as", "open_as"]


def config_as(
    identity: str,
    endpoints: Sequence[str],
    connect_timeout: float = 10.0,
    credentials: str | Path = "",
) -> BusConfig:
    """Return the bus configuration of `identity`: from the `credentials` file if given,
    else `$CBDI_CREDENTIALS`, else the local run's (no user when none are found)."""
    path = credentials or os.environ.get(CREDENTIALS_ENV) or discover(endpoints, identity)
    cfg = BusConfig(connect=tuple(endpoints), connect_timeout=connect_timeout)
    if not path:
        return cfg
    found = read_credentials(Path(path))
    return BusConfig(
        connect=cfg.connect,
        connect_timeout=connect_timeout,
        user=found.user,
        password=found.password,
    )


async def open_as(identity: str, endpoints: Sequence[str], timeout: float = 60.0) -> ZenohBus:
    """Open the bus as `identity`, trying again (once a second) until `timeout` s passed;
    raise the last ConfigError then (it names the endpoints and the user)."""
    clock = WallClock()
    deadline = clock.now() + timeout
    while True:
        try:
            return await open_bus(config_as(identity, endpoints, connect_timeout=1.0))
        except CbdiError as exc:
            if clock.now() >= deadline:
                raise ConfigError("bus", "connect", f"as {identity!r}: {exc}") from None
        await clock.sleep(1.0)
