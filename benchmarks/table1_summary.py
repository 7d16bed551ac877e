"""Table I's rows: per situation and planning speed, both modes' statistics and their
paired difference, from the runs (and the bounds) alone.

A run that did not recycle everything has no moves worth averaging: it is counted as
failed and named, and its seed drops out of the pairing, so every figure says on how
many runs it stands.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from table1_bounds import Bound
from table1_model import SITUATIONS, Run, Situation
from table1_stats import Sample, describe, paired_differences, verdict

__all__ = [
    "ModeStats",
    "Row",
    "clairvoyant_of",
    "factors_of",
    "rows_of",
    "static_of",
]

ONLINE_BETTER, OFFLINE_BETTER = "online better", "offline better"
ONLINE_FASTER, OFFLINE_FASTER = "online faster", "offline faster"


@dataclass(frozen=True)
class ModeStats:
    """One mode's runs of a situation: counts, failures, moves and mission time."""

    runs: int
    failures: tuple[str, ...]  # "seed 3: killed", in seed order
    traces: int  # distinct request traces among the runs that report one
    moves: Sample
    sim_time: Sample

    @property
    def failed(self) -> int:
        """Return how many runs did not recycle everything."""
        return len(self.failures)


@dataclass(frozen=True)
class Row:
    """A situation at one planning speed: both modes, the paired differences, bounds."""

    situation: Situation
    factor: float
    offline: ModeStats
    online: ModeStats
    moves_diff: Sample  # online minus offline, paired by seed
    time_diff: Sample
    moves_verdict: str
    time_verdict: str
    clairvoyant: Sample  # moves of the clairvoyant plans of the row's seeds
    clairvoyant_missing: int  # seeds whose clairvoyant planning found no plan


def mode_stats(runs: Sequence[Run]) -> ModeStats:
    """Summarise one mode's runs (failed ones counted, not averaged)."""
    done = [r for r in runs if r.ok]
    failures = tuple(
        f"seed {r.task.seed}: {r.result}"
        for r in sorted(runs, key=lambda r: r.task.seed)
        if not r.ok
    )
    return ModeStats(
        runs=len(runs),
        failures=failures,
        traces=len({r.trace_digest for r in runs if r.trace_digest}),
        moves=describe([float(r.moves or 0) for r in done]),
        sim_time=describe([float(r.sim_time or 0.0) for r in done]),
    )


def _paired(online: Sequence[Run], offline: Sequence[Run], field: str) -> Sample:
    on = {r.task.seed: float(getattr(r, field)) for r in online if r.ok}
    off = {r.task.seed: float(getattr(r, field)) for r in offline if r.ok}
    return describe([d for _, d in paired_differences(on, off)])


def factors_of(runs: Sequence[Run]) -> list[float]:
    """Return the planning speed factors of the lockstep runs, ascending."""
    return sorted({r.task.factor for r in runs if r.task.clock == "lockstep"})


def rows_of(runs: Sequence[Run], bounds: Sequence[Bound]) -> list[Row]:
    """Return a row per (planning speed, situation) the lockstep runs cover, in paper order."""
    lockstep = [r for r in runs if r.task.clock == "lockstep"]
    rows = []
    for factor in factors_of(lockstep):
        for situation in SITUATIONS:
            mine = [
                r for r in lockstep if r.task.factor == factor and r.task.situation == situation
            ]
            if mine:
                rows.append(_row(situation, factor, mine, bounds))
    return rows


def _row(situation: Situation, factor: float, runs: Sequence[Run], bounds: Sequence[Bound]) -> Row:
    offline = [r for r in runs if r.task.mode == "offline"]
    online = [r for r in runs if r.task.mode == "online"]
    moves_diff = _paired(online, offline, "moves")
    time_diff = _paired(online, offline, "sim_time")
    seeds = sorted({r.task.seed for r in runs})
    found, missing = clairvoyant_of(bounds, situation.move_step, seeds)
    return Row(
        situation=situation,
        factor=factor,
        offline=mode_stats(offline),
        online=mode_stats(online),
        moves_diff=moves_diff,
        time_diff=time_diff,
        moves_verdict=verdict(
            moves_diff, lower_is_better=ONLINE_BETTER, higher_is_better=OFFLINE_BETTER
        ),
        time_verdict=verdict(
            time_diff, lower_is_better=ONLINE_FASTER, higher_is_better=OFFLINE_FASTER
        ),
        clairvoyant=describe([float(m) for m in found]),
        clairvoyant_missing=missing,
    )


def clairvoyant_of(
    bounds: Sequence[Bound], move_step: int, seeds: Sequence[int]
) -> tuple[list[int], int]:
    """Return the clairvoyant moves found for the seeds, and how many seeds have none.

    A seed with no clairvoyant bound at all (not computed) counts as neither.
    """
    by_seed = {b.seed: b for b in bounds if b.kind == "clairvoyant" and b.move_step == move_step}
    found = [by_seed[s].moves for s in seeds if s in by_seed and by_seed[s].moves is not None]
    missing = sum(1 for s in seeds if s in by_seed and by_seed[s].moves is None)
    return [m for m in found if m is not None], missing


def static_of(bounds: Sequence[Bound]) -> Bound | None:
    """Return the static optimum among the bounds, if it was computed."""
    return next((b for b in bounds if b.kind == "static"), None)
