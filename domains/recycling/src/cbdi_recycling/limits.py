"""Limits of the world's seeded chances: people's jitter, action-duration noise, failures.

The world checks them when it is built and the launcher when it reads a scenario or
`cbdi up` flags, so a bad value is reported where it was written, by the same rule.
"""

from __future__ import annotations

import math
from typing import TypeGuard

__all__ = ["MAX_DURATION_NOISE", "chance_problems"]

# A stretch of up to 10x the domain's duration is already far beyond any situation of the
# paper; larger values only make a run crawl.
MAX_DURATION_NOISE = 10.0


def chance_problems(
    people_jitter: object, duration_noise: object, failure_probability: object
) -> list[tuple[str, str]]:
    """Return `(option, reason)` for every value out of range; empty when all are valid.

    The values come from TOML and flags, so their types are checked too: a TOML `true` is
    an `int` to Python, and NaN or infinity would slip through a plain range test.
    """
    problems: list[tuple[str, str]] = []
    if not _integer(people_jitter) or people_jitter < 0:
        problems.append(("people_jitter", f"expected an integer >= 0, got {people_jitter!r}"))
    if not _finite(duration_noise) or not 0 <= duration_noise <= MAX_DURATION_NOISE:
        limit = f"[0, {MAX_DURATION_NOISE:g}]"
        problems.append(("duration_noise", f"expected a number in {limit}, got {duration_noise!r}"))
    if not _finite(failure_probability) or not 0 <= failure_probability < 1:
        problems.append(
            ("failure_probability", f"expected a number in [0, 1), got {failure_probability!r}")
        )
    return problems


def _integer(value: object) -> TypeGuard[int]:
    return isinstance(value, int) and not isinstance(value, bool)


def _finite(value: object) -> TypeGuard[float]:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
