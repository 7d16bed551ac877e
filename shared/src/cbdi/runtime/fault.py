"""Faults injected at a chosen epoch (`CBDI_FAULT`, `--fault`): a crash or a freeze of a
service where a test or a user wants it, not where a poll of the logs happens to land.

A fault is `SERVICE:KIND@EPOCH`, for example `world:kill@12` or `robot1/planner:stop@8`;
several are separated by commas. Every service of a run may get the same list and takes
the faults that name it. The service does it to itself as the world's tick of that epoch
(or the first one after it) reaches it: `kill` is SIGKILL (a crash: nothing is flushed,
nothing closed), `stop` is SIGSTOP (a frozen process, for the freeze watchdog). Only the
first life of a service has faults (`CBDI_RESTART` unset or 0): its restart, by `cbdi up`
or by a container's restart policy, runs on undisturbed.

The world steps epochs in lockstep and in real time alike, so one rule serves both, and
every service, the router and the monitor too, hears the world's clock.
"""

from __future__ import annotations

import os
import re
import signal
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Literal

from cbdi.runtime.life import RESTART_ENV

__all__ = ["FAULT_ENV", "Fault", "FaultKind", "parse_faults", "planned_fault", "strike"]

FAULT_ENV = "CBDI_FAULT"
FaultKind = Literal["kill", "stop"]
SIGNALS: dict[str, signal.Signals] = {"kill": signal.SIGKILL, "stop": signal.SIGSTOP}
MAX_EPOCH = 10**9
_FAULT = re.compile(r"^(?P<service>[A-Za-z0-9_.\-/]+):(?P<kind>[a-z]+)@(?P<epoch>\d{1,10})$")


@dataclass(frozen=True)
class Fault:
    """Do `kind` to `service` once the world's epoch `epoch` reaches it."""

    service: str
    kind: FaultKind
    epoch: int

    def __str__(self) -> str:
        return f"{self.service}:{self.kind}@{self.epoch}"


def parse_faults(texts: Iterable[str]) -> tuple[Fault, ...]:
    """Parse faults (each text may hold several, comma-separated); ValueError names the
    one that is malformed and says what is expected. One fault per service at most."""
    found: dict[str, Fault] = {}
    for text in texts:
        for part in (p.strip() for p in text.split(",")):
            if not part:
                continue
            fault = _parse_one(part)
            if fault.service in found:
                raise ValueError(f"fault {part!r}: {fault.service} has a fault already")
            found[fault.service] = fault
    return tuple(found.values())


def _parse_one(text: str) -> Fault:
    match = _FAULT.match(text)
    if match is None:
        raise ValueError(
            f"fault {text!r}: expected SERVICE:KIND@EPOCH, e.g. world:kill@12 "
            f"(kinds: {', '.join(SIGNALS)})"
        )
    kind, epoch = match["kind"], int(match["epoch"])
    if kind not in SIGNALS:
        raise ValueError(f"fault {text!r}: unknown kind {kind!r} (kinds: {', '.join(SIGNALS)})")
    if epoch > MAX_EPOCH:
        raise ValueError(f"fault {text!r}: epoch {epoch} is past {MAX_EPOCH}")
    service = match["service"]
    if service.startswith("/") or service.endswith("/") or "//" in service:
        raise ValueError(f"fault {text!r}: {service!r} is no service id")
    return Fault(service, kind, epoch)  # type: ignore[arg-type]


def planned_fault(
    service: str, faults: Iterable[Fault], environ: Mapping[str, str] = os.environ
) -> Fault | None:
    """Return the fault planned for `service` in this life: none after a restart."""
    restart = environ.get(RESTART_ENV, "0").strip()
    if restart not in ("", "0"):
        return None
    return next((f for f in faults if f.service == service), None)


def strike(fault: Fault) -> None:
    """Do the fault to this very process (the caller has logged it).

    A container's main process is its namespace's init (pid 1), which the kernel
    shields from signals it sent itself: a kill is then an exit with nothing flushed
    or closed (`os._exit`, code 137 as for SIGKILL), a stop a thread that never again
    lets the event loop turn (the heartbeat stops: frozen)."""
    os.kill(os.getpid(), SIGNALS[fault.kind])
    if os.getpid() != 1:
        return  # a stop continued (SIGCONT): the process goes on
    if fault.kind == "kill":
        os._exit(128 + signal.SIGKILL)
    while True:
        time.sleep(3600)
