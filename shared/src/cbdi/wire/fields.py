"""Constrained field types of wire messages: what a schema-valid message may hold.

Decoding checks these, so a message that is well-formed but nonsense (an empty belief
name, a step time of `inf`, a check operator `move`, a million-element list) is a
`WireError` at the receiver's door, never an exception deep inside a service.
"""

from __future__ import annotations

import sys
from typing import Annotated, TypeVar

import msgspec

__all__ = [
    "MAX_ITEMS",
    "MAX_PROBLEM",
    "MAX_TEXT",
    "AgentName",
    "Atom",
    "Cell",
    "Coordinate",
    "Count",
    "Epoch",
    "Finite",
    "Id",
    "Many",
    "NonNegative",
    "Problem",
    "Symbol",
    "Text",
]

T = TypeVar("T")

MAX_ITEMS = 1_000_000  # elements of one list or map (the facts of a 300x300 map)
MAX_TEXT = 65_536  # characters of a free-text field (reasons, messages)
MAX_PROBLEM = 4_000_000  # characters of a PDDL problem sent to a planner
_BIG = sys.float_info.max

# An agent or component name: one chunk of a key (`cbdi.keys.validate_name`).
AgentName = Annotated[
    str, msgspec.Meta(min_length=1, max_length=63, pattern=r"^[A-Za-z][A-Za-z0-9_\-]*$")
]
# A name of the domain (object, predicate, action, step, plan): never empty.
Symbol = Annotated[str, msgspec.Meta(min_length=1, max_length=256)]
# An identifier that may be empty where the field says so (no baseline, no step).
Id = Annotated[str, msgspec.Meta(max_length=256)]
Text = Annotated[str, msgspec.Meta(max_length=MAX_TEXT)]
Problem = Annotated[str, msgspec.Meta(max_length=MAX_PROBLEM)]
# A ground atom: predicate or function, then its arguments.
Atom = Annotated[list[Symbol], msgspec.Meta(min_length=1, max_length=32)]
# A finite number: NaN and infinities are rejected (the bounds fail for them).
Finite = Annotated[float, msgspec.Meta(ge=-_BIG, le=_BIG)]
NonNegative = Annotated[float, msgspec.Meta(ge=0.0, le=_BIG)]
Epoch = Annotated[int, msgspec.Meta(ge=-1, le=2**53)]
Count = Annotated[int, msgspec.Meta(ge=0, le=2**53)]
Coordinate = Annotated[int, msgspec.Meta(ge=-(2**31), le=2**31)]
Cell = tuple[Coordinate, Coordinate]
# A list of at most MAX_ITEMS elements.
Many = Annotated[list[T], msgspec.Meta(max_length=MAX_ITEMS)]
