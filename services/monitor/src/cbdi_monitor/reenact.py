"""One agent's part of a lockstep recording, as a script to act again (`cbdi replay --check`).

The agent's planner and scheduler are rebuilt and fed what they heard. Everything else
that was recorded becomes the script: each other sender's publications (the world, the
agent's executor, other agents' schedulers and their claims, ...), to be republished by
a stand-in for that sender on the same keys in the recorded order, so that sequence
numbers, and the `sent` counts of the acks among them, are the original ones; and between
them, waits for the rebuilt components' acks where the originals acknowledged, so that no
stand-in runs further ahead of the agent than its original did (an epoch gate keeps only
the last few acks of a sender). What the agent's planner and scheduler published is what
the rebuilt ones must publish again (`Output`, compared by `cbdi_monitor.difference`).

The recorder keeps each message's sequence number on its key, not its sender's `order`
over all keys: a sender's messages are taken in the file's log order, which is the order
it sent them (one Zenoh session delivers in order through the router to the recorder's one
subscriber). A key whose numbers jump (a message not recorded) is noted; one whose numbers
go back is a restarted sender, played by a fresh stand-in.

Pure: records in, a script out. `cbdi_monitor.check` runs it.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass, field

from cbdi import keys
from cbdi.errors import WireError
from cbdi.lockstep import default_sender
from cbdi.wire.agent import AgentRequest
from cbdi.wire.base import decode
from cbdi.wire.common import RunFinished, RunLaunched
from cbdi.wire.world import EpochAck, Tick, WorldInfo
from cbdi_monitor.errors import NotReplayableError, UnknownAgentError
from cbdi_monitor.reader import RecordedMessage

__all__ = [
    "REPLAYED",
    "AgentScript",
    "Ask",
    "Await",
    "Output",
    "Send",
    "Step",
    "in_sent_order",
    "outputs_of",
    "script_of",
    "sender_of",
    "shell_args",
]

REPLAYED = ("planner", "scheduler")  # the components rebuilt; every other sender is played
NOT_SENDERS = ("trace", "monitor", "launcher")  # mirrors and notes nobody in an agent hears
NOT_COMPARED = ("errors",)  # error reports are batched by wall time: not decisions


@dataclass(frozen=True, slots=True)
class Send:
    """Republish `payload` on `key` as `sender` (one stand-in endpoint per sender)."""

    sender: str
    key: str
    payload: bytes


@dataclass(frozen=True, slots=True)
class Await:
    """Wait for the rebuilt `member`'s ack of `epoch` at `stage` (-1 `ready`: its start)."""

    member: str
    epoch: int
    stage: str


@dataclass(frozen=True, slots=True)
class Ask:
    """Ask the rebuilt scheduler `payload` on `key` again: a request stamped with its
    asker's epoch (a sensor of a robot's process, `cbdi.robot`; a peer's rule), which the
    scheduler applies before its percepts of the next epoch, so it is part of the run."""

    key: str
    payload: bytes


Step = Send | Await | Ask


@dataclass(frozen=True, slots=True)
class Output:
    """One message a replayed member published.

    `index` numbers the compared messages on its key from 1 (its sequence number, less the
    `ready` acks before it: how many of those a component sends depends on the wall
    clock); `epoch` and `stage` are those of the member's next ack (what it was working
    on); `position` is its place among the member's publications.
    """

    key: str
    index: int
    seq: int
    payload: bytes
    member: str
    epoch: int
    stage: str
    position: int


@dataclass(frozen=True)
class AgentScript:
    """What replaying `agent` needs, and what its planner and scheduler must publish."""

    agent: str
    steps: list[Step]
    info: bytes  # the world's info (`WorldInfo`): the answer to `cbdi/world/rpc/info`
    outputs: dict[str, list[Output]]
    launched: dict[str, list[str]]  # member -> the arguments it was started with
    last_epoch: int
    notes: list[str] = field(default_factory=list)

    @property
    def members(self) -> list[str]:
        """The rebuilt members (`robot1/planner`, `robot1/scheduler`)."""
        return [keys.member(self.agent, c) for c in REPLAYED]


def sender_of(key: str) -> str | None:
    """Return who published on `key`, or None for what no agent hears (liveliness,
    request mirrors, the monitor's and the launcher's notes)."""
    part = keys.describe(key)
    if part["stream"] == "alive" or part["component"] in NOT_SENDERS or not part["component"]:
        return None
    return default_sender(key)


def script_of(records: Sequence[RecordedMessage], agent: str, path: str) -> AgentScript:
    """Return the script replaying `agent` from a recording's messages (in log order).

    Raise UnknownAgentError if the recording has no planner and scheduler of `agent`, and
    NotReplayableError if it was not made in lockstep or lacks the world's info.
    """
    info_payload, info = _world_info(records, path)
    _check_lockstep(records, path)
    members = [keys.member(agent, c) for c in REPLAYED]
    if not all(m in info.members for m in members):
        raise UnknownAgentError(path, agent, _bdi_agents(info.members))
    steps, notes = _steps(in_sent_order(records), set(members), agent)
    outputs = outputs_of(((m.key, m.seq, m.payload) for m in records), members)
    done = [
        s.epoch for s in steps if isinstance(s, Await) and s.member == members[-1] and s.epoch >= 0
    ]
    return AgentScript(
        agent=agent,
        steps=steps,
        info=info_payload,
        outputs=outputs,
        launched=_launched(records, members),
        last_epoch=max(done, default=-1),
        notes=[*_stalls(records), *notes],
    )


def in_sent_order(records: Sequence[RecordedMessage]) -> list[RecordedMessage]:
    """Return the records in the order they were published (their senders' stamps), not
    received: the recorder's one subscriber hears each sender in order, but two senders
    in no causal order (a loaded router forwarded the scheduler's ack of an epoch before
    the world's percepts it had answered), and a script in log order then waited for the
    ack before sending what it answers: a stall. One host's clock orders them causally;
    a sender's own messages keep their order (the sort is stable, its stamps rise). A
    record with no stamp (0) keeps its place after the one logged before it."""
    keyed: list[tuple[int, int]] = []
    sent = 0
    for i, m in enumerate(records):
        sent = m.publish_ns or sent
        keyed.append((sent, i))
    return [records[i] for _, i in sorted(keyed)]


def _stalls(records: Sequence[RecordedMessage]) -> list[str]:
    """Say if the run had members late beyond the ack timeout: their inputs were released
    by the clock there, which a replay does not repeat."""
    key = keys.world_stream("events")
    for m in records:
        if m.key == key:
            try:
                stalls = decode(m.payload, RunFinished, key).stalls
            except WireError:
                return []
            if stalls:
                late = ", ".join(f"{s} ({n} epochs)" for s, n in sorted(stalls.items()))
                return [f"members were late beyond the ack timeout: {late}; the replay may differ"]
    return []


def _world_info(records: Sequence[RecordedMessage], path: str) -> tuple[bytes, WorldInfo]:
    key = keys.world_stream("info")
    for m in records:
        if m.key == key:
            try:
                return m.payload, decode(m.payload, WorldInfo, key)
            except WireError as exc:
                raise NotReplayableError(f"{path}: the world's info is unreadable: {exc}") from None
    raise NotReplayableError(
        f"{path}: no world info ({key}): the world's start is not in the recording"
    )


def _check_lockstep(records: Sequence[RecordedMessage], path: str) -> None:
    """Refuse a run not made in lockstep: only there do inputs reach a component in an
    order that does not depend on the machine's pace."""
    tick = next((m for m in records if m.key == keys.CLOCK), None)
    if tick is None:
        raise NotReplayableError(f"{path}: no world tick ({keys.CLOCK}) in the recording")
    try:
        lockstep = decode(tick.payload, Tick, keys.CLOCK).lockstep
    except WireError as exc:
        raise NotReplayableError(f"{path}: the first tick is unreadable: {exc}") from None
    if not lockstep:
        raise NotReplayableError(
            f"{path}: not recorded in lockstep (the world's ticks say lockstep=false); only "
            "a lockstep run repeats decision for decision (cbdi up --lockstep)"
        )


def _bdi_agents(members: Iterable[str]) -> list[str]:
    """The agents with every replayed component among the world's members."""
    parts = [m.split("/") for m in members if m.count("/") == 1]
    agents = sorted({a for a, _ in parts})
    return [a for a in agents if all([a, c] in parts for c in REPLAYED)]


def _ack(key: str, payload: bytes) -> EpochAck | None:
    """The ack on `key`, or None if `key` is no ack key or the payload no ack."""
    if keys.describe(key)["stream"] != "ack":
        return None
    try:
        return decode(payload, EpochAck, key)
    except WireError:
        return None


def _heard(key: str, agent: str) -> bool:
    """Whether `agent`'s planner or scheduler may hear `key` (a gap there matters): its
    own keys, the world's about it, the clock, and the group's claims and acks."""
    part = keys.describe(key)
    return part["agent"] == agent or key == keys.CLOCK or part["stream"] in ("claims", "ack")


def _steps(
    records: Sequence[RecordedMessage], members: set[str], agent: str
) -> tuple[list[Step], list[str]]:
    """Turn the recording into sends by stand-ins and waits for the rebuilt members."""
    steps: list[Step] = []
    notes: list[str] = []
    started: set[str] = set()
    lives: dict[str, int] = {}  # sender -> restarts seen
    last: dict[tuple[str, str], int] = {}  # (sender, key) -> last sequence number
    asked = keys.trace(keys.component_rpc(agent, "scheduler", "request")) + "/request"
    for m in records:
        if m.key == asked:
            ask = _epoch_request(m.payload, agent)
            if ask is not None:
                steps.append(ask)
            continue
        sender = sender_of(m.key)
        if sender is None:
            continue
        if sender in members:
            ack = _ack(m.key, m.payload)
            if ack is not None and (ack.stage != "ready" or sender not in started):
                started.add(sender)
                steps.append(Await(sender, ack.epoch, ack.stage))
            continue
        before = last.get((sender, m.key), 0)
        if m.seq and m.seq <= before:
            lives[sender] = lives.get(sender, 0) + 1
            last = {k: n for k, n in last.items() if k[0] != sender}
            notes.append(f"{sender} restarted (sequence of {m.key} went back to {m.seq})")
            before = 0
        if m.seq > before + 1 and _heard(m.key, agent):
            notes.append(f"{m.key}: messages {before + 1}..{m.seq - 1} are not in the file")
        last[(sender, m.key)] = m.seq
        life = lives.get(sender, 0)
        steps.append(Send(f"{sender}#{life}" if life else sender, m.key, m.payload))
    return steps, notes


def _epoch_request(payload: bytes, agent: str) -> Ask | None:
    """The request a recorded mirror shows, to ask again, if it is stamped with an epoch
    (one stamped -1, an operator's, took effect at once: when depends on the pace)."""
    try:
        req = decode(payload, AgentRequest, "request")
    except WireError:
        return None
    if req.epoch < 0:
        return None
    return Ask(keys.agent_request(agent, req.group), payload)


def outputs_of(
    published: Iterable[tuple[str, int, bytes]], members: Collection[str]
) -> dict[str, list[Output]]:
    """Return what `members` published, by key, from `(key, seq, payload)` in order.

    Left out: error reports (`NOT_COMPARED`), `ready` acks (both paced by the clock) and
    an ack sent again as it was (to a restarted world, `cbdi.lockstep.resend_latest_ack`).
    """
    pending: dict[str, list[tuple[str, int, int, bytes]]] = {m: [] for m in members}
    skipped: dict[str, int] = {}
    count = dict.fromkeys(members, 0)
    acked = dict.fromkeys(members, -1)  # the last epoch each member acknowledged
    last: dict[str, tuple[int, str]] = {}  # each member's last ack (epoch, stage)
    out: dict[str, list[Output]] = {}
    for key, seq, payload in published:
        member = sender_of(key)
        if member not in pending or keys.describe(key)["stream"] in NOT_COMPARED:
            continue
        ack = _ack(key, payload)
        again = ack is not None and (ack.epoch, ack.stage) == last.get(member)
        if ack is not None and (ack.stage == "ready" or again):
            skipped[key] = skipped.get(key, 0) + 1
            continue
        count[member] += 1
        pending[member].append((key, seq - skipped.get(key, 0), seq, payload))
        if ack is not None:
            _close(out, member, pending[member], ack.epoch, ack.stage, count[member])
            pending[member], acked[member] = [], ack.epoch
            last[member] = (ack.epoch, ack.stage)
    for member, rest in pending.items():  # after the last ack: the epoch after it
        _close(out, member, rest, acked[member] + 1, "", count[member])
    return out


def _close(
    out: dict[str, list[Output]],
    member: str,
    items: list[tuple[str, int, int, bytes]],
    epoch: int,
    stage: str,
    last_position: int,
) -> None:
    """File a member's messages up to (and with) its ack of `epoch` at `stage`."""
    first = last_position - len(items) + 1
    for i, (key, index, seq, payload) in enumerate(items):
        out.setdefault(key, []).append(
            Output(key, index, seq, payload, member, epoch, stage, first + i)
        )


def _launched(records: Sequence[RecordedMessage], members: list[str]) -> dict[str, list[str]]:
    """The members' arguments as the launcher recorded them (none if it did not)."""
    key = keys.launcher_stream("run")
    for m in records:
        if m.key == key:
            try:
                services = decode(m.payload, RunLaunched, key).services
            except WireError:
                return {}
            return {s: list(a) for s, a in services.items() if s in members}
    return {}


def shell_args(
    script: AgentScript, component: str, agent_file: str, path: str
) -> tuple[list[str], str]:
    """Return the arguments to build `component` of the agent with, and where they (and
    its agent file) come from: the launcher's record, with `agent_file` instead of the
    recorded one if given; else `--agent A --agent-file F` (the agent file's own settings).
    """
    member = keys.member(script.agent, component)
    recorded = script.launched.get(member)
    if recorded is None:
        if not agent_file:
            raise NotReplayableError(
                f"{path}: does not say how {member} was started (not run by cbdi up, or "
                "recorded before it said so): give the agent file with --agent-file FILE"
            )
        args = ["--agent", script.agent, "--agent-file", agent_file]
        return args, "given with --agent-file; other settings: the agent file's"
    if not agent_file:
        return recorded, "as the launcher recorded it"
    return _with_agent_file(recorded, agent_file), "the launcher's, with --agent-file's file"


def _with_agent_file(args: list[str], agent_file: str) -> list[str]:
    """Replace the `--agent-file` argument (or add it)."""
    out: list[str] = []
    skip = False
    for a in args:
        if skip:
            skip = False
        elif a == "--agent-file":
            skip = True
        elif not a.startswith("--agent-file="):
            out.append(a)
    return [*out, "--agent-file", agent_file]
