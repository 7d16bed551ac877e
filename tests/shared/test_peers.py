"""Telling a restarted peer from one that came back with our own session."""

from __future__ import annotations

from cbdi.bus.base import AliveEvent
from cbdi.peers import Peers

ME, EXEC = "cbdi/alive/r1/scheduler", "cbdi/alive/r1/executor"


def test_a_peer_is_first_then_again_after_vanishing_alone() -> None:
    peers = Peers(ME)
    assert peers.observe(AliveEvent(ME, True)) is None
    assert peers.observe(AliveEvent(EXEC, True)) == "first"
    assert peers.observe(AliveEvent(EXEC, False)) is None
    assert peers.observe(AliveEvent(EXEC, True)) == "again"  # it restarted


def test_peers_that_vanish_with_our_own_token_come_back_reconnected() -> None:
    peers = Peers(ME)
    peers.observe(AliveEvent(EXEC, True))
    for key in (EXEC, ME):  # the router went: every token, ours too
        peers.observe(AliveEvent(key, False))
    assert peers.observe(AliveEvent(ME, True)) is None
    assert peers.observe(AliveEvent(EXEC, True)) == "reconnected"
    assert peers.observe(AliveEvent("cbdi/alive/r1/planner", True)) == "first"
    peers.observe(AliveEvent(EXEC, False))
    assert peers.observe(AliveEvent(EXEC, True)) == "again"  # a real restart later
