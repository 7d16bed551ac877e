"""What a restarted recorder already has (`Recorded`), so the history it gets is not
written twice.

A recorder restarted within the run subscribes with history: every publisher's recovery
cache comes first, which holds what was sent while no recorder ran and, before that, much
of what the killed recorder wrote. A sample is already recorded when the earlier parts
hold a message on its key published as late or later with a sequence number as high or
higher (a sender that restarted counts afresh, but publishes later, so it is kept).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from cbdi_monitor.errors import RecordingError
from cbdi_monitor.reader import read_messages
from cbdi_monitor.recorder import part_paths

__all__ = ["Recorded"]


@dataclass
class Recorded:
    """The latest (publish time, sequence) recorded per key."""

    latest: dict[str, tuple[int, int]] = field(default_factory=dict)
    skipped: int = 0

    @classmethod
    def of(cls, base: str | Path) -> Recorded:
        """Read what the recording `base` holds so far (its parts too); raise
        RecordingError if a part cannot be read."""
        done = cls()
        if not any(p.exists() for p in part_paths(Path(base))):
            return done
        for m in read_messages(base):
            mark = (m.publish_ns, m.seq)
            old = done.latest.get(m.key)
            done.latest[m.key] = mark if old is None else max(old, mark)
        return done

    def has(self, key: str, publish_ns: int, seq: int) -> bool:
        """Whether a sample (stamped `publish_ns`, `seq`) is in the earlier parts."""
        old = self.latest.get(key)
        if old is None or not publish_ns:
            return False
        found = publish_ns <= old[0] and seq <= (old[1] or seq)
        self.skipped += found
        return found


def recorded_before(base: str | Path) -> tuple[Recorded, str]:
    """`Recorded.of(base)`, or nothing and why when the earlier parts cannot be read."""
    try:
        return Recorded.of(base), ""
    except RecordingError as exc:
        return Recorded(), str(exc)
