"""The structured log: a line nobody can read any more is lost, never the service."""

from __future__ import annotations

import io

from cbdi.runtime.log import Log


class _Broken(io.StringIO):
    def write(self, text: str) -> int:
        raise BrokenPipeError("the reader is gone")


def test_a_broken_stream_loses_the_line_not_the_service() -> None:
    log = Log("robot1/planner", stream=_Broken())
    log.warning("orphaned", parent=1)
    log.info("stopped", exit_code=0)
    assert log.lost == 2


def test_lines_are_key_value_events() -> None:
    out = io.StringIO()
    Log("world", stream=out).info("finished", reason="time_limit")
    assert "service=world event=finished reason=time_limit" in out.getvalue()
