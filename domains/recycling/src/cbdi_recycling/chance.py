"""What the seed samples besides litter: people's phase and jitter, action noise, failures.

Every purpose draws from its own `random.Random`, seeded with the string
`"{seed}:{purpose}"`: a string seed is hashed with SHA-512, not `hash()`, so a stream is
the same in every process whatever PYTHONHASHSEED is, and turning one option on never
shifts another's draws. Streams are per person and per agent, so an agent's noise and
failures do not depend on the order in which the world hears agents within an epoch.
Litter keeps `random.Random(seed)`, so a seed spawns the same litter as before.
"""

from __future__ import annotations

import math
import random
from collections.abc import Collection, Sequence
from dataclasses import dataclass

from cbdi.wire.world import Cell
from cbdi_recycling.errors import GridError
from cbdi_recycling.limits import chance_problems

__all__ = ["Chance", "countdown", "epochs_of", "fails", "start_index", "stream"]

_EPS = 1e-9


@dataclass(frozen=True)
class Chance:
    """The seeded variations of a run; all off by default, which is the deterministic world.

    `people_phase`: each person starts at a seeded cell of its loop, not `path[0]`.
    `people_jitter`: each countdown to a person's next step is `move_step` plus a seeded
    integer in [-j, j], at least 1. `duration_noise`: an accepted action lasts its domain
    duration stretched by a seeded 0..noise fraction, rounded up to whole epochs.
    `failure_probability`: an accepted action fails at its end with this probability.
    """

    people_phase: bool = False
    people_jitter: int = 0
    duration_noise: float = 0.0
    failure_probability: float = 0.0

    def __post_init__(self) -> None:
        j, noise, p = self.people_jitter, self.duration_noise, self.failure_probability
        problems = chance_problems(j, noise, p)
        if problems:
            raise GridError("; ".join(f"{option}: {reason}" for option, reason in problems))


def stream(seed: int, purpose: str) -> random.Random:
    """Return the generator of one purpose (`people-phase:person1`, `failures:robot1`)."""
    return random.Random(f"{seed}:{purpose}")


def start_index(path: Sequence[Cell], taken: Collection[Cell], rng: random.Random) -> int:
    """Return a seeded index of `path` whose cell is not taken: the drawn one or the next free.

    Raise `GridError` when every cell of the loop is taken (the person has nowhere to
    stand), rather than put two bodies in one cell.
    """
    first = rng.randrange(len(path))
    for k in range(len(path)):
        index = (first + k) % len(path)
        if path[index] not in taken:
            return index
    raise GridError(f"no free cell on the loop {[list(c) for c in path]} to start on")


def countdown(move_step: int, jitter: int, rng: random.Random) -> int:
    """Return the epochs until a person's next step; no draw without jitter (today's pace)."""
    if jitter <= 0:
        return move_step
    return max(1, move_step + rng.randint(-jitter, jitter))


def epochs_of(duration: float, epoch_duration: float, noise: float, rng: random.Random) -> int:
    """Return the whole epochs an action lasts: `duration` stretched by a seeded 0..noise.

    Rounded up so the action ends on an epoch boundary, never before its domain duration
    (the tolerance keeps a duration of exactly k epochs at k despite float error).
    """
    stretched = duration * (1.0 + noise * rng.random())
    return max(1, math.ceil(stretched / epoch_duration - _EPS))


def fails(probability: float, rng: random.Random) -> bool:
    """Draw whether an action fails; one draw per completed action whenever p > 0."""
    return probability > 0 and rng.random() < probability
