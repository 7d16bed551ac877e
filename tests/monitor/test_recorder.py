"""The recorder core, the reader and `inspect` on files written in the test."""

from __future__ import annotations

from pathlib import Path

import pytest

from cbdi.wire import encode
from cbdi.wire.world import ActionOutcome, ActionRequest, Tick
from cbdi_monitor.inspect import inspect_messages
from cbdi_monitor.reader import RecordingError, read_messages
from cbdi_monitor.recorder import McapRecorder, Rotation
from cbdi_monitor.schemas import json_schema, peek_schema, wire_classes

S = 1_000_000_000


def tick(epoch: int) -> bytes:
    return encode(
        Tick(epoch=epoch, time=float(epoch), epoch_duration=1.0, speed=1.0, lockstep=False)
    )


def test_round_trip_keeps_keys_times_sequences_and_schemas(tmp_path: Path) -> None:
    rec = McapRecorder(tmp_path / "r.mcap")
    for i in range(5):
        rec.write("cbdi/world/clock", tick(i), log_ns=S * (i + 1), publish_ns=S * i, seq=i + 1)
    rec.write("cbdi/odd", b"\xc1 not msgpack", log_ns=S * 9)
    rec.close()
    got = list(read_messages(tmp_path / "r.mcap"))
    assert [m.seq for m in got[:5]] == [1, 2, 3, 4, 5]
    assert got[0].publish_ns == S  # no publish time from the sender: the log time stands in
    assert got[1].publish_ns == S and got[1].log_ns == 2 * S
    assert {m.schema for m in got} == {"cbdi.world.Tick/1", ""}
    assert got[-1].payload == b"\xc1 not msgpack"  # recorded as is, never dropped
    assert rec.counts == {"cbdi/world/clock": 5, "cbdi/odd": 1}
    rec.write("cbdi/late", tick(9), log_ns=S * 10)
    assert rec.late == 1  # after close: counted, not written


def test_rotation_by_duration_splits_files(tmp_path: Path) -> None:
    rec = McapRecorder(tmp_path / "run.mcap", Rotation(max_seconds=2.0))
    for i in range(6):
        rec.write("cbdi/world/clock", tick(i), log_ns=S * i)
    rec.close()
    assert [p.name for p in rec.files] == ["run.mcap", "run-001.mcap", "run-002.mcap"]
    assert sum(1 for f in rec.files for _ in read_messages(f)) == 6


def test_schemas_are_known_by_name() -> None:
    assert peek_schema(tick(1)) == "cbdi.world.Tick/1"
    assert peek_schema(b"\x00\x01") == ""
    assert "cbdi.world.Percepts/1" in wire_classes()
    assert b'"epoch"' in json_schema("cbdi.world.Tick/1")
    assert json_schema("nope/1") == b""


def test_reader_refuses_a_file_that_is_not_mcap(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"certainly not mcap")
    with pytest.raises(RecordingError, match="not a readable MCAP"):
        list(read_messages(bad))
    with pytest.raises(RecordingError, match="No such file"):
        list(read_messages(tmp_path / "missing.mcap"))


def test_inspect_counts_moves_failures_and_first_action(tmp_path: Path) -> None:
    rec = McapRecorder(tmp_path / "r.mcap")
    rec.write("cbdi/world/clock", tick(0), log_ns=S)
    rec.write("cbdi/world/clock", tick(3), log_ns=2 * S)
    rec.write(
        "cbdi/trace/world/rpc/act/request",
        encode(ActionRequest(agent="r1", action="move", request_id="1", target=(1, 0))),
        log_ns=3 * S,
    )
    for status, reason in (("succeeded", ""), ("failed", "blocked by person p")):
        rec.write(
            "cbdi/world/outcomes/r1",
            encode(
                ActionOutcome(
                    agent="r1",
                    request_id="1",
                    action="move",
                    status=status,
                    reason=reason,
                    epoch=4,
                    time=4.0,
                )
            ),
            log_ns=4 * S,
        )
    rec.write("cbdi/world/outcomes/r1", b"garbage", log_ns=5 * S)
    rec.close()
    report = inspect_messages(read_messages(tmp_path / "r.mcap"))
    agent = report.agents["r1"]
    assert (agent.moves, agent.failed, agent.requests) == (1, 1, 1)
    assert agent.first_action_time == 3.0
    assert agent.actions == {"move:succeeded": 1, "move:failed": 1}
    assert report.undecodable == 1 and report.messages == 6 and report.duration_s == 4.0
