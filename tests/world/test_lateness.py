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
            over.append((k, said))
    assert over == [(4, {"seconds": 0.3}), (9, {"seconds": 2.0})]  # what the world logs
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


def test_a_late_epoch_says_where_its_time_went() -> None:
    tally = Lateness(epoch_wall=1.0)
    assert tally.observe(due=10.0, out=10.05, woke=10.0, begin=10.01) is None  # on time
    said = tally.observe(due=11.0, out=11.5, woke=11.25, begin=11.3)
    assert said == {"seconds": 0.5, "woke": 0.25, "step": 0.05, "publish": 0.2}
