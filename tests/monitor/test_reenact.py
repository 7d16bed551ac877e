"""Replaying one agent (`cbdi replay --check`), the pure parts: the script a recording
becomes, what counts as a difference, and the refusals (exit 2) of what cannot be replayed.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from cbdi import keys
from cbdi.wire.agent import BeliefsUpdate
from cbdi.wire.base import Message, encode
from cbdi.wire.common import RunFinished, RunLaunched
from cbdi.wire.planner import SearchRound
from cbdi.wire.world import EpochAck, Tick, WorldInfo
from cbdi_monitor import replay
from cbdi_monitor.difference import compare, fields_of
from cbdi_monitor.errors import NotReplayableError, UnknownAgentError
from cbdi_monitor.reader import RecordedMessage
from cbdi_monitor.recorder import McapRecorder
from cbdi_monitor.reenact import Await, Output, Send, outputs_of, script_of, shell_args

MEMBERS = ["robot1/planner", "robot1/scheduler", "robot1/executor"]
INFO = WorldInfo(
    map_name="m", agents=["robot1"], epoch_duration=1.0, durations={}, members=MEMBERS,
)  # fmt: skip


def ack(component: str, epoch: int, stage: str = "done", **sent: int) -> EpochAck:
    counts = {f"cbdi/robot1/{component}/{k}": n for k, n in sent.items()}
    return EpochAck(agent="robot1", component=component, epoch=epoch, stage=stage, sent=counts)


def tick(epoch: int, lockstep: bool = True) -> Tick:
    return Tick(epoch=epoch, time=float(epoch), epoch_duration=1.0, speed=0.0, lockstep=lockstep)


def beliefs(epoch: int, facts: list[list[str]]) -> BeliefsUpdate:
    return BeliefsUpdate(
        agent="robot1", time=float(epoch), instances={}, facts=facts, fluents=[], epoch=epoch
    )


def records(*items: tuple[str, Message]) -> list[RecordedMessage]:
    """Messages as recorded, each key's numbered from 1 in order."""
    seqs: dict[str, int] = {}
    out = []
    for i, (key, msg) in enumerate(items):
        seqs[key] = seqs.get(key, 0) + 1
        out.append(RecordedMessage(key, encode(msg), i, i, seqs[key], "", "msgpack"))
    return out


SCHED_ACK = keys.epoch_ack("robot1", "scheduler")
RUN = records(
    (keys.launcher_stream("run"), RunLaunched(scenario="s", services={"robot1/planner": ["-x"]})),
    (keys.world_stream("info"), INFO),
    (SCHED_ACK, ack("scheduler", -1, "ready")),
    (SCHED_ACK, ack("scheduler", -1, "ready")),  # paced by the wall clock
    (keys.CLOCK, tick(0)),
    (keys.scheduler_beliefs("robot1"), beliefs(0, [["a"]])),
    (SCHED_ACK, ack("scheduler", 0, "beliefs", beliefs=1)),
    (SCHED_ACK, ack("scheduler", 0, "done", beliefs=1)),
    (keys.executor_status("robot1"), beliefs(0, [])),  # any message will do
)


def test_an_ack_logged_before_what_it_answers_is_awaited_after_sending_that() -> None:
    """Under load the recorder may log the scheduler's ack of an epoch before the world's
    message it answered (two senders, no causal order at the recorder): the script goes
    by publication time, so it sends the tick before it waits for the ack."""
    run = list(RUN)
    tick0, beliefs0, acked = run[4], run[5], run[6]
    # Logged: the ack first, then the tick and the beliefs; published: tick, beliefs, ack.
    logged = [
        RecordedMessage(acked.key, acked.payload, 4, 6, acked.seq, "", "msgpack"),
        RecordedMessage(tick0.key, tick0.payload, 5, 4, tick0.seq, "", "msgpack"),
        RecordedMessage(beliefs0.key, beliefs0.payload, 6, 5, beliefs0.seq, "", "msgpack"),
    ]
    script = script_of([*run[:4], *logged, *run[7:]], "robot1", "f.mcap")
    assert script.steps[2:4] == [
        Send("world", keys.CLOCK, tick0.payload),
        Await("robot1/scheduler", 0, "beliefs"),
    ]


def test_a_recording_becomes_stand_ins_sends_and_waits_for_the_rebuilt_members() -> None:
    script = script_of(RUN, "robot1", "f.mcap")
    assert script.steps == [
        Send("world", keys.world_stream("info"), RUN[1].payload),
        Await("robot1/scheduler", -1, "ready"),  # once: how often it says so is not decided
        Send("world", keys.CLOCK, RUN[4].payload),
        Await("robot1/scheduler", 0, "beliefs"),
        Await("robot1/scheduler", 0, "done"),
        Send("robot1/executor", keys.executor_status("robot1"), RUN[8].payload),
    ]
    assert script.last_epoch == 0 and script.notes == []
    assert script.launched == {"robot1/planner": ["-x"]}
    assert shell_args(script, "planner", "", "f") == (["-x"], "as the launcher recorded it")
    with pytest.raises(NotReplayableError, match="--agent-file"):
        shell_args(script, "scheduler", "", "f")
    args, _ = shell_args(script, "scheduler", "a.toml", "f")
    assert args == ["--agent", "robot1", "--agent-file", "a.toml"]


def test_a_message_not_in_the_file_is_noted_and_a_restarted_sender_gets_a_new_stand_in() -> None:
    status = keys.executor_status("robot1")
    run = [*RUN]
    for seq in (3, 1):  # 2 is not in the file; then the executor starts afresh
        run.append(RecordedMessage(status, RUN[8].payload, 20 + seq, 0, seq, "", "msgpack"))
    run.append(RecordedMessage(keys.SNAPSHOT, b"", 30, 0, 7, "", "msgpack"))  # nobody hears it
    end = RunFinished(reason="done", epoch=1, time=1.0, stalls={"robot1/executor": 2})
    run.append(RecordedMessage(keys.EVENTS, encode(end), 31, 0, 1, "", "msgpack"))
    script = script_of(run, "robot1", "f.mcap")
    assert script.notes == [
        "members were late beyond the ack timeout: robot1/executor (2 epochs); the replay may"
        " differ",
        f"{status}: messages 2..2 are not in the file",
        f"robot1/executor restarted (sequence of {status} went back to 1)",
    ]
    senders = [s.sender for s in script.steps if isinstance(s, Send) and s.key == status]
    assert senders == ["robot1/executor", "robot1/executor", "robot1/executor#1"]


def test_outputs_are_numbered_without_ready_acks_and_dated_by_the_next_ack() -> None:
    out = outputs_of(((m.key, m.seq, m.payload) for m in RUN), ["robot1/scheduler"])
    belief = out[keys.scheduler_beliefs("robot1")][0]
    assert (belief.index, belief.epoch, belief.stage) == (1, 0, "beliefs")
    acks = out[SCHED_ACK]
    assert [(a.index, a.seq, a.epoch, a.stage) for a in acks] == [
        (1, 3, 0, "beliefs"),
        (2, 4, 0, "done"),
    ]


def test_a_difference_is_named_by_field_and_epoch_and_measurements_are_not_one() -> None:
    def rounds(seconds: float, expanded: int) -> bytes:
        return encode(
            SearchRound(
                agent="robot1", request_id="r", plan_id="p", purpose="new", number=1,
                kind="k", mode="G", expanded=expanded, seconds=seconds, best_h=0,
                plan_actions=0, time=0.0,
            )
        )  # fmt: skip

    assert fields_of(rounds(0.5, 10), rounds(0.7, 10)) == []  # how fast, not what
    (diff,) = fields_of(rounds(0.5, 10), rounds(0.5, 11))
    assert (diff.path, diff.recorded, diff.replayed) == ("expanded", 10, 11)
    (items,) = fields_of(encode(beliefs(3, [["a"], ["b"]])), encode(beliefs(3, [["b"]])))
    assert (items.recorded, items.replayed) == ([["a"]], [])

    recorded = outputs_of(((m.key, m.seq, m.payload) for m in RUN), ["robot1/scheduler"])
    later = [*RUN[:5], *records((keys.scheduler_beliefs("robot1"), beliefs(0, [["b"]])))]
    replayed = outputs_of(((m.key, m.seq, m.payload) for m in later), ["robot1/scheduler"])
    verdict = compare(recorded, replayed)
    assert not verdict.same and verdict.first is not None
    first = verdict.first
    assert (first.key, first.index, first.epoch, first.kind) == (
        keys.scheduler_beliefs("robot1"),
        1,
        0,
        "differs",
    )
    assert compare(recorded, recorded).matched == 3


def test_beliefs_sent_as_changes_or_whole_are_the_same_beliefs() -> None:
    from cbdi.beliefs import BeliefSet, BeliefsSender, fact

    sets = [BeliefSet.of([fact("in", "r", f"c_{k}"), fact("free", "c_9")]) for k in range(4)]
    key = keys.scheduler_beliefs("robot1")

    def series(sender: BeliefsSender, resend_at: int = -1) -> dict[str, list[Output]]:
        out = []
        for k, b in enumerate(sets):
            if k == resend_at:
                sender.resend()  # the planner appeared then: that update went whole
            payload = encode(sender.update(b, float(k), k))
            out.append(Output(key, k + 1, k + 1, payload, "robot1/scheduler", k, "beliefs", k))
        return {key: out}

    recorded = series(BeliefsSender("robot1"), resend_at=2)
    assert compare(recorded, series(BeliefsSender("robot1"))).same
    sets[3] = sets[3].adding([fact("free", "c_8")])  # one belief more in the last set
    assert not compare(recorded, series(BeliefsSender("robot1"))).same


def test_what_the_replay_sent_after_the_recording_ended_is_not_a_difference() -> None:
    next_ack = encode(ack("scheduler", 1, "beliefs"))  # the run stopped before the original's
    further = [*RUN, RecordedMessage(SCHED_ACK, next_ack, 9, 9, 5, "", "msgpack")]
    members = ["robot1/scheduler"]
    recorded = outputs_of(((m.key, m.seq, m.payload) for m in RUN), members)
    replayed = outputs_of(((m.key, m.seq, m.payload) for m in further), members)
    verdict = compare(recorded, replayed)
    assert verdict.same and (verdict.matched, verdict.unverified) == (3, 1)


def write(path: Path, items: list[RecordedMessage]) -> Path:
    rec = McapRecorder(path)
    for m in items:
        rec.write(m.key, m.payload, m.log_ns + 1, m.publish_ns + 1, m.seq)
    rec.close()
    return path


@pytest.mark.parametrize(
    ("content", "agent", "error"),
    [
        ("text", "robot1", "not a readable MCAP file"),  # shorter than the magic bytes
        ("not an MCAP file but a longer text", "robot1", "not a readable MCAP file"),
        (RUN, "robot9", "no planner and scheduler of agent 'robot9' (BDI agents in it: robot1)"),
        (records((keys.world_stream("info"), INFO), (keys.CLOCK, tick(0, lockstep=False))),
         "robot1", "not recorded in lockstep"),
        (records((keys.CLOCK, tick(0)),), "robot1", "no world info"),
    ],
)  # fmt: skip
def test_what_cannot_be_replayed_is_refused_in_one_line(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    content: str | list[RecordedMessage],
    agent: str,
    error: str,
) -> None:
    path = tmp_path / "run.mcap"
    if isinstance(content, str):
        path.write_text(content)
    else:
        write(path, content)
    assert replay.main([str(path), "--agent", agent, "--check"]) == 2
    err = capsys.readouterr().err
    assert error in err and err.count("\n") == 1 and "Traceback" not in err


def test_unknown_agent_error_names_the_agents_there_are() -> None:
    err = UnknownAgentError("f", "x", [])
    assert "holds no BDI agent" in str(err)
