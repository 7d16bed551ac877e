"""The recorder core, the reader and `inspect` on files written in the test."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from cbdi.wire import encode
from cbdi.wire.world import (
    ActionOutcome,
    ActionRequest,
    Tick,
)
from cbdi_monitor import export, inspect, view
from cbdi_monitor.inspect import inspect_messages
from cbdi_monitor.reader import RecordingError, read_messages
from cbdi_monitor.recorder import GARBAGE_PER_KEY, GARBAGE_TOTAL, McapRecorder, Rotation
from cbdi_monitor.resume import recorded_before
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
    assert got[-1].payload == b"\xc1 not msgpack"  # recorded as is (the first ones)
    assert rec.counts == {"cbdi/world/clock": 5, "cbdi/odd": 1}
    rec.write("cbdi/late", tick(9), log_ns=S * 10)
    assert rec.late == 1  # after close: counted, not written


def test_rotation_by_duration_splits_files(tmp_path: Path) -> None:
    rec = McapRecorder(tmp_path / "run.mcap", Rotation(max_seconds=2.0))
    for i in range(6):
        rec.write("cbdi/world/clock", tick(i), log_ns=S * i)
    rec.close()
    assert [p.name for p in rec.files] == ["run.mcap", "run-001.mcap", "run-002.mcap"]
    assert [m.log_ns for m in read_messages(tmp_path / "run.mcap")] == [S * i for i in range(6)]


def _killed(rec: McapRecorder) -> None:
    """Leave `rec` as a recorder killed outright leaves its file: flushed, not finished."""
    rec.flush()
    assert rec._stream is not None
    rec._stream.flush()
    rec._stream, rec._writer = None, None  # no footer is ever written


def test_a_killed_recorder_loses_nothing_it_flushed_and_its_restart_goes_on(
    tmp_path: Path,
) -> None:
    base = tmp_path / "run.mcap"
    first = McapRecorder(base)
    for i in range(5):
        first.write("cbdi/world/clock", tick(i), log_ns=S * i)
    _killed(first)
    assert [m.log_ns for m in read_messages(base)] == [S * i for i in range(5)]
    again = McapRecorder(base, resume=True)  # the restart: never overwrites
    for i in range(5, 9):
        again.write("cbdi/world/clock", tick(i), log_ns=S * i)
    again.close()
    assert [p.name for p in again.files] == ["run-001.mcap"]
    assert [m.log_ns for m in read_messages(base)] == [S * i for i in range(9)]
    # A file cut in the middle of a record reads up to the cut.
    data = base.read_bytes()
    base.write_bytes(data[: len(data) - 7])
    assert [m.log_ns for m in read_messages(base)][-4:] == [S * i for i in range(5, 9)]
    # A new recording replaces the file and drops the earlier one's parts.
    fresh = McapRecorder(base)
    fresh.write("cbdi/world/clock", tick(0), log_ns=S * 42)
    fresh.close()
    assert not (tmp_path / "run-001.mcap").exists()
    assert [m.log_ns for m in read_messages(base)] == [S * 42]


def test_a_restart_knows_what_the_killed_recorder_wrote(tmp_path: Path) -> None:
    """The history a restarted recorder gets holds what the earlier parts have: those are
    skipped; what is newer on a key, or a restarted sender's (counting afresh, later),
    is not; unreadable earlier parts are reported, not fatal."""
    base = tmp_path / "run.mcap"
    first = McapRecorder(base)
    for i in range(5):
        first.write("cbdi/world/clock", tick(i), log_ns=S * i, publish_ns=S * i, seq=i + 1)
    _killed(first)
    done, why = recorded_before(base)
    assert not why and done.latest == {"cbdi/world/clock": (4 * S, 5)}
    assert done.has("cbdi/world/clock", 3 * S, 4) and done.has("cbdi/world/clock", 4 * S, 5)
    assert not done.has("cbdi/world/clock", 5 * S, 6)  # sent while no recorder ran
    assert not done.has("cbdi/world/clock", 6 * S, 1)  # a restarted sender
    assert not done.has("cbdi/other", S, 1)
    assert done.skipped == 2
    assert recorded_before(tmp_path / "none.mcap")[0].latest == {}
    base.write_bytes(b"not an MCAP file at all")
    nothing, why = recorded_before(base)
    assert nothing.latest == {} and "not a readable MCAP file" in why


def test_schemas_are_known_by_name() -> None:
    assert peek_schema(tick(1)) == "cbdi.world.Tick/1"
    assert peek_schema(b"\x00\x01") == ""
    assert "cbdi.recycling.Percepts/1" in wire_classes()
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
    assert (agent.failed, agent.requests) == (1, 1)
    assert agent.first_action_time == 3.0
    assert agent.actions == {"move:succeeded": 1, "move:failed": 1}
    assert report.undecodable == 1 and report.messages == 6 and report.duration_s == 4.0


def test_garbage_is_recorded_in_part_and_the_rest_counted(tmp_path: Path) -> None:
    rec = McapRecorder(tmp_path / "r.mcap")
    for i in range(1000):  # a flood of garbage queries, mirrored on one trace key
        rec.write("cbdi/trace/world/rpc/act/request", b"\xc1" * 100, log_ns=S + i)
    for i in range(3000):  # and on ever new keys
        rec.write(f"cbdi/junk{i}/x/y", b"not msgpack", log_ns=2 * S + i)
    assert rec.write("cbdi/world/clock", tick(1), log_ns=3 * S)  # real traffic: always
    rec.close()
    assert rec.garbage["cbdi/trace/world/rpc/act/request"] == GARBAGE_PER_KEY
    assert sum(rec.garbage.values()) == GARBAGE_TOTAL
    assert sum(rec.dropped.values()) == 4000 - GARBAGE_TOTAL
    got = list(read_messages(tmp_path / "r.mcap"))
    assert len(got) == GARBAGE_TOTAL + 1 and got[-1].key == "cbdi/world/clock"
    # the trace key, the junk keys kept, the clock: no channel for a dropped key
    assert len(rec.counts) == 1 + (GARBAGE_TOTAL - GARBAGE_PER_KEY) + 1


def test_export_keeps_the_channel_metadata(tmp_path: Path) -> None:
    rec = McapRecorder(tmp_path / "r.mcap")
    status = encode(
        ActionOutcome(
            agent="robot1",
            request_id="1",
            action="move",
            status="failed",
            reason="x",
            epoch=1,
            time=1.0,
        )
    )
    rec.write("cbdi/world/outcomes/robot1", status, log_ns=S)
    rec.write("cbdi/world/clock", tick(0), log_ns=S)
    rec.close()
    assert export.main([str(tmp_path / "r.mcap"), "--json", str(tmp_path / "j.mcap")]) == 0
    original = {m.key: dict(m.metadata) for m in read_messages(tmp_path / "r.mcap")}
    exported = {m.key: dict(m.metadata) for m in read_messages(tmp_path / "j.mcap")}
    assert exported == original
    outcome = exported["cbdi/world/outcomes/robot1"]
    assert {"agent", "component", "stream", "schema"} <= set(outcome)
    assert (outcome["agent"], outcome["component"]) == ("robot1", "world")


def test_damaged_recordings_give_exit_2_and_a_message(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = McapRecorder(tmp_path / "good.mcap")
    for i in range(300):
        rec.write("cbdi/world/clock", tick(i), log_ns=S + i, seq=i + 1)
    rec.close()
    data = (tmp_path / "good.mcap").read_bytes()
    bad, out = tmp_path / "bad.mcap", tmp_path / "out"
    rng = random.Random("mcap")
    variants = [b"", b"\x89MCAP0\r\n", b"certainly not mcap", data[:34], data[:150]]
    for _ in range(30):
        i = rng.randrange(len(data))
        variants.append(data[:i] + bytes([rng.randrange(256)]) + data[i + 1 :])
    refused = 0
    for variant in variants:
        bad.write_bytes(variant)
        codes = {
            inspect.main([str(bad)]),
            export.main([str(bad), "--json", str(out)]),
            view.main([str(bad), "--rrd", str(tmp_path / "out.rrd")]),
        }
        assert codes <= {0, 2}, variant
        if 2 in codes:
            refused += 1
            assert "not a readable MCAP file" in capsys.readouterr().err
            assert not out.exists()  # a failed export leaves no half copy
        out.unlink(missing_ok=True)
    assert refused >= 6


class _Log:
    def __init__(self) -> None:
        self.events: list[tuple[str, dict[str, object]]] = []

    def info(self, event: str, **kw: object) -> None:
        self.events.append((event, kw))

    warning = info


class _Replay:
    """A subscription that hands out fixed samples, then waits (as a live one does)."""

    def __init__(self, samples: list[object]) -> None:
        self.samples, self.closed = samples, False

    def __aiter__(self) -> object:
        return self._go()

    async def _go(self) -> object:
        import asyncio

        for s in self.samples:
            yield s
        await asyncio.Event().wait()

    async def close(self) -> None:
        self.closed = True


def test_a_restarted_recorder_catches_up_what_its_first_history_lacked(
    tmp_path: Path,
) -> None:
    """The second ask of the caches writes what was sent while no recorder ran and is in
    neither the earlier part nor what the first history gave, each once; samples sent
    after the recorder began are the live subscription's, not the catch-up's."""
    import asyncio
    import collections
    import types

    from cbdi.bus.base import Sample
    from cbdi_monitor.service import Monitor

    base = tmp_path / "run.mcap"
    first = McapRecorder(base)
    for i in range(5):
        first.write("cbdi/world/clock", tick(i), log_ns=S * i, publish_ns=S * i, seq=i + 1)
    _killed(first)
    before, _ = recorded_before(base)

    def sample(i: int) -> Sample:
        return Sample("cbdi/world/clock", tick(i), seq=i + 1, sent_ns=S * i)

    replay = _Replay([sample(i) for i in (3, 4, 5, 6, 7, 9)])
    log = _Log()
    ctx = types.SimpleNamespace(
        bus=types.SimpleNamespace(subscribe=lambda key, history: replay),
        counters=collections.Counter(),
        log=log,
    )
    monitor = Monitor(ctx, McapRecorder(base, resume=True), 0.1, before)  # type: ignore[arg-type]
    monitor.began_ns = S * 8 + 1  # began after epoch 8 was sent
    monitor.write(sample(7))  # the first history had 7 only (and live 8)
    monitor.write(Sample("cbdi/world/clock", tick(8), seq=9, sent_ns=S * 8))
    asyncio.run(monitor.catch_up(after=0, limit=0.5))
    monitor.recorder.close()
    assert replay.closed
    assert sorted(int(m.log_ns // S) for m in read_messages(base)) == list(range(9))
    assert ("caught_up", {"samples": 2}) in log.events
    assert ctx.counters["recovered"] == 4 and ctx.counters["caught_up"] == 2
