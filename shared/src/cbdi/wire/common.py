"""Wire types used by every service: errors on the bus, acknowledgements, run control."""

from __future__ import annotations

from cbdi.wire.base import Message

__all__ = [
    "ErrorReply",
    "ErrorReport",
    "Liveliness",
    "RunFinished",
    "RunLaunched",
    "ServiceHealth",
]


class ErrorReply(Message, frozen=True, tag="cbdi.ErrorReply/1"):
    """Answer a request that could not be served; `code` is machine-readable.

    Codes in use: `bad_message` (undecodable payload), `unknown_agent`, `internal`.
    """

    code: str
    message: str


class ErrorReport(Message, frozen=True, tag="cbdi.ErrorReport/1"):
    """Report bad input a service received and survived, on its error stream."""

    service: str
    key: str
    code: str
    message: str
    count: int


class RunFinished(Message, frozen=True, tag="cbdi.RunFinished/1"):
    """Announce that a run ended: `reason` is `done` (all litter recycled) or `time_limit`."""

    reason: str
    epoch: int
    time: float
    # Lockstep: members that missed the ack timeout, with how many epochs they stalled.
    stalls: dict[str, int] = {}
    # The world's request trace: how many requests, and the digest of all of them.
    requests: int = 0
    trace_digest: str = ""


class RunLaunched(Message, frozen=True, tag="cbdi.RunLaunched/1"):
    """Say how the launcher started a run's services, before the world starts.

    Each service id's command-line arguments (after the program), so that a recording
    tells how to build any of its services again (`cbdi replay --check`).
    """

    scenario: str
    services: dict[str, list[str]]


class Liveliness(Message, frozen=True, tag="cbdi.Liveliness/1"):
    """A liveliness token appeared or vanished (as recorded by the monitor)."""

    key: str
    alive: bool


class ServiceHealth(Message, frozen=True, tag="cbdi.ServiceHealth/1"):
    """The monitor's word that a service appeared or disappeared, and who is alive now."""

    service: str
    alive: bool
    alive_now: list[str]
