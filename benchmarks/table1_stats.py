"""Statistics of Table I: means, deviations, bootstrap intervals and paired differences.

Pure functions over numbers. Every bootstrap draws from its own numpy Generator seeded
with `BOOTSTRAP_SEED`, so an interval depends only on the values it is given, never on
what was computed before it: the same CSV renders the same table, to the last digit.
"""

from __future__ import annotations

import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "BOOTSTRAP_RESAMPLES",
    "BOOTSTRAP_SEED",
    "LEVEL",
    "MIN_PAIRS",
    "Interval",
    "Sample",
    "bootstrap_interval",
    "describe",
    "paired_differences",
    "verdict",
]

BOOTSTRAP_SEED = 20230701
BOOTSTRAP_RESAMPLES = 10_000
LEVEL = 0.95
MIN_PAIRS = 3  # fewer paired seeds than this give no verdict: an interval of 2 says little


@dataclass(frozen=True)
class Interval:
    """A two-sided interval; `low <= high`."""

    low: float
    high: float

    def excludes_zero(self) -> bool:
        """Tell whether zero lies outside the interval (a difference is clear)."""
        return self.low > 0 or self.high < 0


@dataclass(frozen=True)
class Sample:
    """What the table says of a sample: its size, mean, deviation and bootstrap interval."""

    n: int
    mean: float | None
    sd: float | None
    interval: Interval | None


def bootstrap_interval(
    values: Sequence[float],
    *,
    level: float = LEVEL,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> Interval | None:
    """Return the percentile bootstrap interval of the mean (None for no values).

    The values are sorted first so that their order (which run finished first) cannot
    change the interval.
    """
    if not values:
        return None
    data = np.array(sorted(values), dtype=float)
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, len(data), size=(resamples, len(data)))
    means = data[picks].mean(axis=1)
    tail = (1.0 - level) / 2.0 * 100.0
    low, high = np.percentile(means, [tail, 100.0 - tail])
    # A mean of resampled values lies within them; rounding in the vectorised mean may
    # put it an ulp outside (one value 7.0 gave 6.999...): clamp, so equal values give
    # exactly their value on every machine.
    lo, hi = float(data[0]), float(data[-1])
    return Interval(min(max(float(low), lo), hi), min(max(float(high), lo), hi))


def describe(values: Sequence[float]) -> Sample:
    """Return size, mean, sample standard deviation (n-1) and bootstrap interval."""
    if not values:
        return Sample(0, None, None, None)
    ordered = sorted(values)
    sd = statistics.stdev(ordered) if len(ordered) > 1 else 0.0
    return Sample(len(ordered), statistics.fmean(ordered), sd, bootstrap_interval(ordered))


def paired_differences(
    first: Mapping[int, float], second: Mapping[int, float]
) -> list[tuple[int, float]]:
    """Return `(seed, first - second)` for every seed both have, in seed order.

    Pairing by seed compares runs of the same world (same people, same noise): the
    difference then measures the planning mode, not the luck of the draw.
    """
    return [(seed, first[seed] - second[seed]) for seed in sorted(set(first) & set(second))]


def verdict(diff: Sample, *, lower_is_better: str, higher_is_better: str) -> str:
    """Say which side a paired difference favours, if its interval excludes zero."""
    if diff.n < MIN_PAIRS or diff.interval is None:
        return f"too few pairs ({diff.n} < {MIN_PAIRS})"
    if diff.interval.high < 0:
        return lower_is_better
    if diff.interval.low > 0:
        return higher_is_better
    return "no clear difference"
