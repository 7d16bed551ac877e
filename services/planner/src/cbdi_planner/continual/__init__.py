"""Continual planning (the paper's CJFF): search rounds, re-rooting, commitment, forecast."""

from __future__ import annotations

from cbdi_planner.continual.execution import (
    COMMITTED_FAILS,
    FAILS_LATER,
    HOLDS,
    Commitment,
    Forecast,
    Sensed,
    commit,
    forecast,
)
from cbdi_planner.continual.rounds import NG, G, Round, RoundBound, SearchSpace
from cbdi_planner.continual.thread import (
    Event,
    ImprovedPlan,
    ModeChanged,
    Outdated,
    PartialPlanFound,
    RoundDone,
    SearchFailed,
    SearchThread,
    segment,
)

__all__ = [
    "COMMITTED_FAILS",
    "FAILS_LATER",
    "HOLDS",
    "NG",
    "Commitment",
    "Event",
    "Forecast",
    "G",
    "ImprovedPlan",
    "ModeChanged",
    "Outdated",
    "PartialPlanFound",
    "Round",
    "RoundBound",
    "RoundDone",
    "SearchFailed",
    "SearchSpace",
    "SearchThread",
    "Sensed",
    "commit",
    "forecast",
    "segment",
]
