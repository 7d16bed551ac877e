"""docs/your-own-domain.md names every member of the Simulator protocol and every field
of `WorldInfo`: a member the protocol gains, and the doc does not name, fails here."""

from __future__ import annotations

import re

import msgspec

from cbdi.simulator import Simulator, SimulatorClass
from cbdi.wire.world import WorldInfo
from tests_support import REPO

DOC = (REPO / "docs" / "your-own-domain.md").read_text(encoding="utf-8")
SECTION = DOC[DOC.index("### The protocol, member by member") : DOC.index("A robot that acts")]
# Read by the host through getattr, not declared by the protocol classes.
OPTIONAL = ("needs_map", "Options", "performs", "save_state", "restore_state")


def _members(protocol: type) -> set[str]:
    """The public members a protocol class declares (methods, properties, attributes)."""
    own = set(vars(protocol)) | set(getattr(protocol, "__annotations__", {}))
    return {m for m in own if not m.startswith("_")}


def _headed() -> set[str]:
    """The members the section's list items are about: the names in backquotes that
    open an item (`- `epoch: int` and `time: float`: ...` names epoch and time)."""
    found: set[str] = set()
    for line in SECTION.splitlines():
        head = re.match(r"- ((?:`[^`]+`(?: and |, )?)+)", line)
        if head:
            found |= set(re.findall(r"`(\w+)", head.group(1)))
    return found


def test_every_member_of_the_simulator_protocol_is_documented() -> None:
    declared = _members(Simulator) | _members(SimulatorClass) | set(OPTIONAL) | {"__init__"}
    assert {"epoch", "time", "done", "info", "request", "initial", "step", "stats"} <= declared
    missing = sorted(declared - _headed())
    assert not missing, f"docs/your-own-domain.md does not name {missing}"


def test_every_worldinfo_field_is_in_the_table() -> None:
    table = SECTION[SECTION.index("### What `WorldInfo` needs") :]
    fields = [f.name for f in msgspec.structs.fields(WorldInfo)]
    missing = [f for f in fields if f"`{f}`" not in table]
    assert not missing, f"the WorldInfo table does not name {missing}"
