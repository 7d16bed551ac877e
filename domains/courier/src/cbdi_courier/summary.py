"""The courier domain's summary counters (entry point `cbdi.counters`): what a report
such as `cbdi inspect` counts per robot, by the actions whose successes count."""

from __future__ import annotations

__all__ = ["COUNTERS"]

# counter -> the PDDL action (ActionOutcome.action) whose successes it counts
COUNTERS = {"drives": "drive", "drops": "drop", "charges": "charge"}
