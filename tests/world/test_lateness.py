"""How late a paced world had its epochs out (`cbdi_world.lateness`)."""

from __future__ import annotations

import math

import pytest

from cbdi_world.lateness import Lateness


def test_the_distribution_of_lateness_and_the_epochs_over_a_tenth() -> None:
    tally = Lateness(epoch_wall=1.0)
    over = []
    for k, late in enumerate([0.0, 0.01, 0.02, 0.05, 0.3, -0.01, 0.09, 0.0, 0.0, 2.0]):
        said = tally.observe(due=float(k), out=k + late)  # an early one counts as on time
        if said is not None:
            over.append((k, round(said, 6)))
    assert over == [(4, 0.3), (9, 2.0)]  # the epochs over the bound, as the world logs them
    s = tally.summary()
    assert s is not None
    assert (s.epochs, s.bound, s.over, s.max) == (10, 0.1, 2, 2.0)
    assert s.median == pytest.approx(0.015) and s.p95 == 2.0


def test_a_run_not_paced_has_no_lateness() -> None:
    flat = Lateness(epoch_wall=0.0)
    flat.observe(due=0.0, out=5.0)
    assert flat.summary() is None and Lateness(0.25).summary() is None


@pytest.mark.parametrize("wall", [math.nan, math.inf, -1.0])
def test_a_nonsensical_epoch_duration_is_refused(wall: float) -> None:
    with pytest.raises(ValueError, match="wall duration"):
        Lateness(wall)
