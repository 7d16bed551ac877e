"""The world's state on disk, so a killed world goes on where it was (`StateFile`).

Every few epochs (`--state-every`), right after the simulator stepped and before the
epoch is published, the host saves a `WorldState`: the simulator (its `save_state()`
bytes, or the pickled object), the epoch's result, the request trace and the lockstep
marks. What changes the world between two saves is appended to the same file as it
happens: each request served with its reply (`Served`, before the reply goes out),
each step (`Stepped`, with the lockstep marks then) and that an epoch went out
(`Published`). A world restarted by `cbdi up` (`CBDI_RESTART` above 0) reads the file
back (`StateFile.load`) and replays the entries on the restored simulator, in order (the
same requests and steps give the same replies and epochs: the simulator is
deterministic), then goes on: the same items, people, robots, random generators,
pending actions, trace and stalls. A whole save costs about a millisecond (a 30x30 map,
8 robots), an entry some microseconds.

The file is written whole to a temporary file and renamed over the old one (a reader
never sees half a state), and entries are appended with a length and a CRC each, so a
torn or foreign tail is found and cut. Nothing is synced to the disk: the file survives
a killed process (the kernel has the data), not a lost machine. It is local, private
state written by the world itself (pickle, never from the network).
"""

from __future__ import annotations

import os
import pickle
import struct
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from cbdi.runtime.log import Log
from cbdi.simulator import EpochResult, Simulator
from cbdi.wire.world import ActionReply, ActionRequest
from cbdi_world.errors import WorldError
from cbdi_world.trace import RequestTrace

__all__ = [
    "Entry",
    "Keeper",
    "Published",
    "Recovered",
    "Served",
    "StateFile",
    "StateFileError",
    "Stepped",
    "WorldState",
    "restored_simulator",
    "simulator_state",
]

MAGIC = b"cbdi-world-state/1\n"
_HEAD = struct.Struct("<II")  # length and CRC-32 of one record


class StateFileError(WorldError):
    """Refuse a state file that is missing, foreign, damaged or of another simulator."""

    code = "bad_state_file"

    def __init__(self, path: str | Path, reason: str) -> None:
        self.path = str(path)
        super().__init__(f"state file {path}: {reason}")


@dataclass
class WorldState:
    """What the host saves each epoch (the simulator as bytes: see `simulator_state`)."""

    simulator: bytes
    result: EpochResult  # the epoch the simulator is at, published or about to be
    trace: RequestTrace
    acked: dict[str, tuple[int, int]] = field(default_factory=dict)
    behind: dict[str, int] = field(default_factory=dict)
    stalls: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class Served:
    """A request the world served in `epoch`, and its reply."""

    epoch: int
    request: ActionRequest
    reply: ActionReply


@dataclass(frozen=True)
class Stepped:
    """The simulator stepped to `epoch`; the lockstep marks as they were then."""

    epoch: int
    acked: dict[str, tuple[int, int]] = field(default_factory=dict)
    behind: dict[str, int] = field(default_factory=dict)
    stalls: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class Published:
    """Epoch `epoch` went out on the bus."""

    epoch: int


Entry = Served | Stepped | Published


@dataclass
class Recovered:
    """A state read back: the saved state, and what happened after it, in order."""

    state: WorldState
    entries: list[Entry]


def simulator_state(simulator: Simulator) -> bytes:
    """Return a simulator's state: its own `save_state()`, else the pickled object."""
    save = getattr(simulator, "save_state", None)
    if callable(save):
        return bytes(save())
    return pickle.dumps(simulator, protocol=pickle.HIGHEST_PROTOCOL)


def restored_simulator(fresh: Simulator, data: bytes, path: str | Path = "") -> Simulator:
    """Return the simulator `data` saved: `fresh` (built from the same settings) after its
    own `restore_state(data)`, else the unpickled object, which must be of its class."""
    restore = getattr(fresh, "restore_state", None)
    try:
        if callable(restore):
            restore(data)
            return fresh
        simulator = pickle.loads(data)
    except Exception as exc:  # whatever a damaged state makes the simulator raise
        raise StateFileError(path, f"the simulator's state does not load: {exc}") from None
    if type(simulator) is not type(fresh):
        kind = type(simulator).__name__
        raise StateFileError(path, f"holds a {kind}, not a {type(fresh).__name__}")
    return simulator


class StateFile:
    """One world's state file: `save` a state, `note` what follows it, `load` it back."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._log: IO[bytes] | None = None
        self._end = 0  # where the last whole record read back ends

    def save(self, state: WorldState) -> None:
        """Replace the file by `state` (atomically: written aside, then renamed)."""
        self.close()
        tmp = self.path.with_name(self.path.name + ".tmp")
        with tmp.open("wb") as f:
            f.write(MAGIC + _record(state))
        os.replace(tmp, self.path)
        self._log = self.path.open("ab", buffering=0)  # each entry one write(2)

    def open_log(self) -> None:
        """Go on noting after what `load` read (a torn tail cut off), as after `save`."""
        self.close()
        with self.path.open("r+b") as f:
            f.truncate(self._end)
        self._log = self.path.open("ab", buffering=0)

    def note(self, entry: Entry) -> None:
        """Append what happened after the saved state (no-op before the first save)."""
        if self._log is not None:
            self._log.write(_record(entry))

    def close(self) -> None:
        if self._log is not None:
            self._log.close()
            self._log = None

    def load(self) -> Recovered:
        """Read the state and the entries after it; StateFileError if there is none."""
        try:
            data = self.path.read_bytes()
        except OSError as exc:
            raise StateFileError(self.path, exc.strerror or str(exc)) from None
        if not data.startswith(MAGIC):
            raise StateFileError(self.path, "not a cbdi world state (no header)")
        records, self._end = _records(data, len(MAGIC))
        if not records or not isinstance(records[0], WorldState):
            raise StateFileError(self.path, "no whole state in it")
        entries = [r for r in records[1:] if isinstance(r, Served | Stepped | Published)]
        return Recovered(records[0], entries)


def _record(item: object) -> bytes:
    payload = pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL)
    return _HEAD.pack(len(payload), zlib.crc32(payload)) + payload


def _records(data: bytes, at: int) -> tuple[list[object], int]:
    """The whole records from `at` on and where they end; a torn or damaged one ends
    the list."""
    found: list[object] = []
    while at + _HEAD.size <= len(data):
        size, crc = _HEAD.unpack_from(data, at)
        payload = data[at + _HEAD.size : at + _HEAD.size + size]
        if len(payload) < size or zlib.crc32(payload) != crc:
            break
        try:
            found.append(pickle.loads(payload))
        except Exception:  # a record of code that changed since: the end of what we know
            break
        at += _HEAD.size + size
    return found, at


class Keeper:
    """A world's state file as the host keeps it: never the world's death. A file that
    cannot be written is given up, with a warning; one that cannot be read back (missing,
    damaged, of another world) is a warning naming it, and the world starts afresh."""

    def __init__(self, path: str | Path, log: Log) -> None:
        self.file: StateFile | None = StateFile(path)
        self.path, self.log = str(path), log

    def recover(self, fresh: Simulator) -> tuple[Simulator, Recovered] | None:
        """Return the simulator saved and what followed it; None: start afresh."""
        assert self.file is not None
        try:
            recovered = self.file.load()
            simulator = restored_simulator(fresh, recovered.state.simulator, self.path)
            if simulator.info() != fresh.info():
                raise StateFileError(self.path, "of another world (its map or agents differ)")
            self.file.open_log()
        except (StateFileError, OSError) as exc:
            self.log.warning("state_unusable", state=self.path, reason=str(exc), then="afresh")
            return None
        return simulator, recovered

    def save(self, state: WorldState) -> None:
        self._keep(lambda f: f.save(state))

    def note(self, entry: Entry) -> None:
        self._keep(lambda f: f.note(entry))

    def close(self) -> None:
        if self.file is not None:
            self.file.close()

    def discard(self) -> None:
        """Close and delete the file: the run it would go on with has ended."""
        self.close()
        self.file = None
        try:
            Path(self.path).unlink(missing_ok=True)
        except OSError as exc:
            self.log.warning("state_not_removed", state=self.path, reason=exc.strerror or str(exc))

    def _keep(self, write: Callable[[StateFile], None]) -> None:
        if self.file is None:
            return
        try:
            write(self.file)
        except OSError as exc:
            self.log.warning("state_not_saved", state=self.path, error=str(exc), then="none")
            self.file.close()
            self.file = None
