"""The recycling domain's binding: its PDDL actions as the grid world performs them."""

from __future__ import annotations

import pytest
from cbdi_recycling.binding import ACTIONS, UnboundActionError, cell_of, load_binding

from cbdi.errors import ConfigError
from cbdi.plugins import installed
from cbdi.wire.world import ActionRequest


def call(action: str, *args: str) -> ActionRequest:
    return ActionRequest(agent="r", action=action, request_id="1", args=list(args))


def test_each_pddl_action_becomes_the_worlds_own() -> None:
    binding = load_binding("recycling")
    assert binding.actions == ACTIONS == ("move", "litter_pickup", "recycle")
    move = binding.primitive(call("move", "r", "c_0_1", "c_12_3"))
    assert (move.action, move.target, move.item, move.args) == ("move", (12, 3), None, [])
    pick = binding.primitive(call("litter_pickup", "r", "pla61", "c_6_1"))
    assert (pick.action, pick.item) == ("pickup", "pla61")
    bin_ = binding.primitive(call("RECYCLE", "r", "pla61", "bin", "c_0_1", "c_0_0"))
    assert (bin_.action, bin_.item, bin_.request_id) == ("recycle", "pla61", "1")


@pytest.mark.parametrize(
    ("req", "why"),
    [
        (call("drive", "r", "c_0_0", "c_0_1"), "performs no action 'drive'"),
        (call("move", "r", "c_0_0"), "too few arguments (3 needed)"),
        (call("move", "r", "c_0_0", "kitchen"), "'kitchen' is not a cell name"),
    ],
)
def test_what_the_world_cannot_perform_is_an_error_with_the_reason(
    req: ActionRequest, why: str
) -> None:
    with pytest.raises(UnboundActionError, match=why.replace("(", r"\(").replace(")", r"\)")):
        load_binding("recycling").primitive(req)
    assert cell_of("c_2_5") == (2, 5)


def test_a_binding_that_is_not_installed_is_a_config_error() -> None:
    assert "recycling" in installed("cbdi.bindings")
    with pytest.raises(ConfigError, match=r"--binding: binding: no action binding 'warehouse'"):
        load_binding("warehouse", "--binding")
