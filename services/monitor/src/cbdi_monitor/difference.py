"""Compare what a replayed agent published with what its original published.

Messages are paired per key by their index (`reenact.Output.index`: the sequence number
less the clock-paced `ready` acks), and must have been sent in the same epoch and stage
and be equal field by field after msgpack decoding, except for measurements
(`MEASUREMENTS`): fields that say how fast this machine was, not what the agent decided.
Today that is one: `SearchRound.seconds`, the wall time a search round took. Everything
else, sim times and acks' `sent` counts included, must be equal. Belief updates are
compared as the whole sets they give (`whole_sets`): whether the scheduler sent one whole
or as a change depends on when its planner and executor appeared on the bus, not on what
the agent believed.

A replayed message whose recorded twin is missing from the file is counted as unverified,
not as a difference: a key published without blocking whose message was dropped on the
way to the recorder, or what the replay published after the member's last recorded ack
(the run, and the recorder, stopped before the original got that far). Pure: no I/O.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import msgpack

from cbdi.beliefs import BeliefsReceiver, to_wire
from cbdi.errors import WireError
from cbdi.lockstep import stage_rank
from cbdi.wire.agent import BeliefsUpdate
from cbdi.wire.base import decode, encode
from cbdi_monitor.reenact import REPLAYED, Output

__all__ = [
    "MEASUREMENTS",
    "WHEN",
    "Difference",
    "FieldDifference",
    "Verdict",
    "compare",
    "fields_of",
    "whole_sets",
]

# schema -> its top-level fields that are measurements, left out of the comparison
MEASUREMENTS: dict[str, frozenset[str]] = {
    "cbdi.planner.SearchRound/1": frozenset({"seconds"}),  # wall seconds of the round
}
MAX_FIELDS = 8  # field differences kept per message
WHEN = "(sent in epoch, stage)"  # the path of a difference in when, not what


@dataclass(frozen=True, slots=True)
class FieldDifference:
    """One field that differs: its path (`steps[0].start`), recorded and replayed values."""

    path: str
    recorded: Any
    replayed: Any


@dataclass(frozen=True)
class Difference:
    """A message that differs (`differs`), was not replayed (`missing`) or was replayed
    beyond what was recorded (`extra`).

    `epoch` and `stage` are when it was published, in the recording or in the replay,
    whichever came first (`recorded_epoch`: when in the recording, -1 if not there).
    """

    kind: str
    key: str
    index: int
    seq: int  # the recorded message's sequence number (the replayed one's if extra)
    member: str
    epoch: int
    stage: str
    position: int  # among the member's publications, on the side `epoch` is from
    recorded_epoch: int = -1
    fields: tuple[FieldDifference, ...] = ()
    message: Any = None  # the decoded message of the side `epoch` is from

    def moment(self) -> tuple[int, int, int, int]:
        """When in the run it happened: epoch, stage, component, place among its
        component's publications."""
        return (*_moment(self.epoch, self.stage, self.member), self.position)


@dataclass(frozen=True)
class Verdict:
    """How the replay went: counts, and the first difference in run order (if any)."""

    matched: int
    differing: int
    unverified: int
    keys: int
    first: Difference | None

    @property
    def same(self) -> bool:
        return self.differing == 0


def compare(
    recorded: Mapping[str, Sequence[Output]], replayed: Mapping[str, Sequence[Output]]
) -> Verdict:
    """Compare every key's messages; the first difference is the earliest in the run."""
    recorded, replayed = whole_sets(recorded), whole_sets(replayed)
    matched = unverified = 0
    found: list[Difference] = []
    ends = _ends(recorded)
    for key in sorted(set(recorded) | set(replayed)):
        ours = {o.index: o for o in recorded.get(key, ())}
        theirs = {o.index: o for o in replayed.get(key, ())}
        last = max(ours, default=0)
        for index in sorted(set(ours) | set(theirs)):
            was, now = ours.get(index), theirs.get(index)
            if was is None and (index < last or _after(now, ends)):
                unverified += 1
            elif was is None:
                found.append(_difference("extra", None, now))
            elif now is None:
                found.append(_difference("missing", was, None))
            elif diff := [*_when(was, now), *fields_of(was.payload, now.payload)]:
                found.append(_difference("differs", was, now, tuple(diff)))
            else:
                matched += 1
    first = min(found, key=Difference.moment) if found else None
    keys = len(set(recorded) | set(replayed))
    return Verdict(matched, len(found), unverified, keys, first)


def whole_sets(outputs: Mapping[str, Sequence[Output]]) -> dict[str, list[Output]]:
    """Return `outputs` with every belief update as the whole set it gives (a change
    whose base is missing stays as it is, and so differs)."""
    out: dict[str, list[Output]] = {}
    for key, messages in outputs.items():
        receiver = BeliefsReceiver()
        rebuilt: list[Output] = []
        for o in sorted(messages, key=lambda o: o.index):
            try:
                update = decode(o.payload, BeliefsUpdate)
            except WireError:
                rebuilt.append(o)
                continue
            beliefs = receiver.apply(update)
            if beliefs is not None:
                whole = to_wire(beliefs, update.agent, update.time, update.epoch)
                o = replace(o, payload=encode(whole))
            rebuilt.append(o)
        out[key] = rebuilt
    return out


def _ends(recorded: Mapping[str, Sequence[Output]]) -> dict[str, tuple[int, int, int]]:
    """When each member's last recorded ack came: the file ends there for it."""
    ends: dict[str, tuple[int, int, int]] = {}
    for o in (o for outputs in recorded.values() for o in outputs if o.stage):
        moment = _moment(o.epoch, o.stage, o.member)
        ends[o.member] = max(ends.get(o.member, moment), moment)
    return ends


def _after(now: Output | None, ends: Mapping[str, tuple[int, int, int]]) -> bool:
    """Whether a replayed message came after its member's last recorded ack (the run was
    stopped, or the recorder with it, before the original got that far)."""
    assert now is not None
    end = ends.get(now.member)
    return end is not None and _moment(now.epoch, now.stage, now.member) > end


def _when(was: Output, now: Output) -> list[FieldDifference]:
    """The same message sent in another epoch (or stage) is another decision. A recorded
    one after its member's last recorded ack has an epoch but no stage."""
    if (was.epoch, was.stage) == (now.epoch, now.stage):
        return []
    if not was.stage and was.epoch == now.epoch:
        return []
    return [FieldDifference(WHEN, (was.epoch, was.stage), (now.epoch, now.stage))]


def _moment(epoch: int, stage: str, member: str) -> tuple[int, int, int]:
    """Order within an epoch: the scheduler's beliefs, the planner's rounds, the
    scheduler's plans (stages by rank, components in `REPLAYED` order), then after."""
    rank = stage_rank(stage) if stage else len(REPLAYED) + 1
    return (epoch, rank, REPLAYED.index(member.rsplit("/", 1)[-1]))


def _difference(
    kind: str, was: Output | None, now: Output | None, fields: tuple[FieldDifference, ...] = ()
) -> Difference:
    """The difference between a recorded message and its replayed twin (either may be
    missing), dated by whichever of them came first."""
    sides = [o for o in (was, now) if o is not None]
    first = min(sides, key=lambda o: (*_moment(o.epoch, o.stage, o.member), o.position))
    seq = was.seq if was is not None else first.seq
    recorded_epoch = was.epoch if was is not None else -1
    return Difference(
        kind,
        first.key,
        first.index,
        seq,
        first.member,
        first.epoch,
        first.stage,
        first.position,
        recorded_epoch,
        fields,
        _decoded(first.payload),
    )


def fields_of(recorded: bytes, replayed: bytes) -> list[FieldDifference]:
    """Return the fields that differ between two payloads (at most `MAX_FIELDS`)."""
    if recorded == replayed:
        return []
    was, now = _decoded(recorded), _decoded(replayed)
    if isinstance(was, dict) and isinstance(now, dict):
        ignored = MEASUREMENTS.get(str(was.get("schema", "")), frozenset())
        was = {k: v for k, v in was.items() if k not in ignored}
        now = {k: v for k, v in now.items() if k not in ignored}
    out: list[FieldDifference] = []
    _diff("", was, now, out)
    return out[:MAX_FIELDS]


_ABSENT = "<absent>"


def _decoded(payload: bytes) -> Any:
    try:
        return msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError):
        return payload  # not msgpack: compared as bytes


def _diff(path: str, was: Any, now: Any, out: list[FieldDifference]) -> None:
    """Append the differences between `was` and `now` under `path`, depth first."""
    if len(out) >= MAX_FIELDS or (type(was) is type(now) and was == now):
        return
    if isinstance(was, dict) and isinstance(now, dict):
        for k in [*was, *(k for k in now if k not in was)]:
            _diff(f"{path}.{k}" if path else str(k), was.get(k, _ABSENT), now.get(k, _ABSENT), out)
    elif isinstance(was, list) and isinstance(now, list) and len(was) == len(now):
        for i, (a, b) in enumerate(zip(was, now, strict=True)):
            _diff(f"{path}[{i}]", a, b, out)
    elif isinstance(was, list) and isinstance(now, list):  # items added or removed
        only_was = [x for x in was if x not in now]
        only_now = [x for x in now if x not in was]
        out.append(FieldDifference(f"{path} (items in one only)", only_was, only_now))
    else:
        out.append(FieldDifference(path or "(payload)", was, now))
