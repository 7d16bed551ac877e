"""Three BDI robots (nine processes and the world) share the 15x15 warehouse's litter,
with both cores loaded and the schedulers started late (virtual time: neither matters)."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest

from cbdi.wire import decode
from cbdi.wire.agent import Claim
from cbdi.wire.world import ActionOutcome, WorldSnapshot
from cbdi_monitor.reader import read_messages
from tests_support import cbdi_up, cpu_load

pytestmark = pytest.mark.e2e


@pytest.mark.timeout(600)  # a whole 3-robot warehouse run beside CPU burners
def test_three_bdi_robots_recycle_all_litter_with_no_item_picked_twice(tmp_path: Path) -> None:
    rec = tmp_path / "three.mcap"
    late = [f"--delay=robot{i}/scheduler={i}" for i in (1, 2, 3)]
    with cpu_load():
        result = cbdi_up(
            "warehouse-15x15-bdi", "--json", "--quiet", "--record", str(rec), *late, timeout=600
        )
    assert result.returncode == 0, result.stderr[-3000:]
    summary = json.loads(result.stdout)
    assert summary["result"] == "done"
    agents = summary["stats"]["agents"]
    assert summary["stats"]["litter_recycled"] == 9 and summary["stats"]["litter_on_ground"] == 0
    assert all(a["recycled"] > 0 for a in agents.values()), agents  # every robot took part
    # Steps started, by action name: the world's counts (it performs them all here).
    for name, a in agents.items():
        performed = summary["performed"][name]
        started = a["moves"] + a["blocked"] + a["failed"]  # a step that failed ran too
        assert a["moves"] <= performed["move"] <= started, (name, performed, a)
        assert a["pickups"] <= performed["litter_pickup"] <= a["pickups"] + a["failed"]
        assert a["recycled"] <= performed["recycle"] <= a["recycled"] + a["failed"]

    recorded = list(read_messages(rec))
    outcomes = [
        decode(m.payload, ActionOutcome)
        for m in recorded
        if m.key.startswith("cbdi/world/outcomes/")
    ]
    picked = [
        (o.agent, o.item) for o in outcomes if o.action == "pickup" and o.status == "succeeded"
    ]
    assert len(picked) == 9 and len({item for _, item in picked}) == 9  # nobody picked twice
    claims = [decode(m.payload, Claim) for m in recorded if m.key.endswith("/scheduler/claims")]
    assert {c.agent for c in claims} == {"robot1", "robot2", "robot3"}
    for snap in (
        decode(m.payload, WorldSnapshot) for m in read_messages(rec, ["cbdi/world/snapshot"])
    ):
        cells = Counter(tuple(a.cell) for a in snap.agents)
        assert max(cells.values()) == 1, f"two robots on one cell at epoch {snap.epoch}"
        people = {tuple(p.cell) for p in snap.people}
        assert not people & set(cells), f"a robot on a person's cell at epoch {snap.epoch}"
