"""Wire types used by every service: errors on the bus, acknowledgements, run control."""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from cbdi.wire.base import Message
from cbdi.wire.fields import Count, Finite, Id, Many, NonNegative, Symbol, Text

__all__ = [
    "EpochLateness",
    "ErrorReply",
    "ErrorReport",
    "Heartbeat",
    "Liveliness",
    "RunFinished",
    "RunLaunched",
    "ServiceFrozen",
    "ServiceHealth",
    "ServiceStarved",
    "Share",
]


class ErrorReply(Message, frozen=True, tag="cbdi.ErrorReply/1"):
    """Answer a request that could not be served; `code` is machine-readable.

    Codes in use: `bad_message` (undecodable payload), `unknown_agent`, `internal`.
    """

    code: Id
    message: Text


class ErrorReport(Message, frozen=True, tag="cbdi.ErrorReport/1"):
    """Report bad input a service received and survived, on its error stream."""

    service: Id
    key: Text
    code: Id
    message: Text
    count: Count


class EpochLateness(Message, frozen=True, tag="cbdi.EpochLateness/1"):
    """How late a paced world (`--speed` above 0) had its epochs out: per epoch, the wall
    seconds from its due time to the end of its publication (tick, outcomes, percepts).
    `over`: the epochs later than `bound`, a tenth of an epoch's wall duration."""

    epochs: Count
    median: NonNegative
    p95: NonNegative
    max: NonNegative
    bound: NonNegative
    over: Count


class RunFinished(Message, frozen=True, tag="cbdi.RunFinished/1"):
    """Announce that a run ended: `reason` is `done` (the world reached its goal) or
    `time_limit`."""

    reason: Symbol
    epoch: Count
    time: Finite
    # Lockstep: members that missed the ack timeout, with how many epochs they stalled.
    stalls: Annotated[dict[Symbol, Count], msgspec.Meta(max_length=10_000)] = {}
    # The world's request trace: how many requests, and the digest of all of them.
    requests: Count = 0
    trace_digest: Id = ""
    # Paced runs: how late the epochs went out (wall time: not part of the digest).
    lateness: EpochLateness | None = None
    # Lockstep: what the world and every member had published before the last epoch, per
    # key (the members' acks of the epoch before, the world's own counts): a listener that
    # counts messages counts that many of each key, waiting for the late ones, and not
    # what the last tick set off while the run ended.
    sent: Annotated[dict[Symbol, Count], msgspec.Meta(max_length=10_000)] = {}


class RunLaunched(Message, frozen=True, tag="cbdi.RunLaunched/1"):
    """Say how the launcher started a run's services, before the world starts.

    Each service id's command-line arguments (after the program), so that a recording
    tells how to build any of its services again (`cbdi replay --check`).
    """

    scenario: Text
    services: Annotated[dict[Symbol, Many[Text]], msgspec.Meta(max_length=10_000)]


class Liveliness(Message, frozen=True, tag="cbdi.Liveliness/1"):
    """A liveliness token appeared or vanished (as recorded by the monitor)."""

    key: Text
    alive: bool


class ServiceHealth(Message, frozen=True, tag="cbdi.ServiceHealth/1"):
    """The monitor's word that a service appeared or disappeared, and who is alive now."""

    service: Text
    alive: bool
    alive_now: Many[Text]


Share = Annotated[float, msgspec.Meta(ge=0.0, le=4096.0)]  # of a time, summed over threads


class Heartbeat(Message, frozen=True, tag="cbdi.Heartbeat/1"):
    """Say that a service's event loop still turns: sent every `--heartbeat` wall seconds.

    From a task of the loop, so a blocked loop or a stopped process falls silent while
    its Zenoh session (and liveliness token) may live on. Wall-clock by nature, it
    never enters a lockstep epoch. `pid` tells one start of a service from the next.

    While the loop stands (`cbdi.runtime.stall`), the process's stall watcher sends it
    from its own thread instead, with the evidence: the loop has not turned for
    `stalled_for` s (0: sent by the loop), its thread ran `loop_cpu` s meanwhile, and the
    process's threads ran or waited runnable for a CPU `wanted` of the time (None:
    unknown), and whether the loop stands in a send on the bus (`sending`: waiting for
    room on a congested network). A process that wanted the CPU and got little is
    starved, one waiting for the network congested; neither is frozen.

    Sent by the loop, it says how the loop kept pace since the last heartbeat: `held`,
    the most CPU the loop's own thread ran between two turns of the stall watcher's
    marker (which turns every `min(0.1, heartbeat / 2)` s): at most what one piece of
    the service's code held the loop for, the same on a loaded machine as on an idle
    one; and `late`, the most the marker woke later than asked (wall time: the load's
    and other threads' share included).
    """

    service: Symbol
    pid: Count
    beat: Count
    stalled_for: NonNegative = 0.0
    loop_cpu: NonNegative = 0.0
    wanted: Share | None = None
    sending: bool = False
    held: NonNegative = 0.0
    late: NonNegative = 0.0


class ServiceStarved(Message, frozen=True, tag="cbdi.ServiceStarved/1"):
    """The launcher's word that a service's loop has not turned for `stalled_for` wall
    seconds for want of what the machine lacked: `cause` `cpu`, its process got too
    little CPU (its threads wanted it `wanted` of the time), or `bus`, its loop waits in
    a send for room on a congested network. Slow, not frozen, so it is not killed."""

    service: Symbol
    pid: Count
    stalled_for: NonNegative
    wanted: Share
    cause: Literal["cpu", "bus"] = "cpu"


class ServiceFrozen(Message, frozen=True, tag="cbdi.ServiceFrozen/1"):
    """The launcher's word that a service sent no heartbeat for `silent_for` wall seconds
    (more than its `limit`): it is killed, and its restart policy decides what next."""

    service: Symbol
    pid: Count
    silent_for: NonNegative
    limit: NonNegative
