"""Whether a task's durative actions can be searched as whole, compressed actions.

A compressed action is its start followed at once by its end: the search appends both
steps together, so no state has a running action and the space shrinks to that of a
classical task. The timeline still lifts the steps into a partial order, so the plan
keeps the concurrency that does not change any state. This is complete only when no
plan *needs* one action to run while another starts or ends (required concurrency).
That need is recognised here, conservatively, by its symptom: a fact that an action
makes true only while it runs (added at start, deleted at end) which another action
reads, or false only while it runs which another action reads negatively, or a
numeric variable an action changes at start and changes back at end, which another
action reads. An action whose own end needs what its start removes is usable only
with another action's help, so it also needs concurrency.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from cbdi_planner.task import GroundAction, Task

__all__ = ["needs_concurrency"]


def needs_concurrency(task: Task) -> bool:
    """Tell whether some plan of `task` may require overlapping actions.

    A function of the actions alone, so told once per grounding: a planner searches
    many tasks of the same actions (one per request and epoch), and on a small map
    this costs as much as the search.
    """
    key = id(task.actions)
    with _LOCK:
        found = _TOLD.get(key)
        if found is not None and found[1] is task.actions:
            _TOLD.move_to_end(key)
            return found[0]
    told = _needs_concurrency(task)
    with _LOCK:
        _TOLD[key] = (told, task.actions)  # the entry holds what the key's id names
        while len(_TOLD) > TOLD:
            _TOLD.popitem(last=False)
    return told


TOLD = 8  # groundings remembered (least recently used forgotten first)
_TOLD: OrderedDict[int, tuple[bool, object]] = OrderedDict()
_LOCK = threading.Lock()


def _needs_concurrency(task: Task) -> bool:
    temp_true = temp_false = temp_num = 0
    for action in task.actions:
        end = action.end
        if end is None:
            continue
        start = action.start
        if end.pre & start.dele & ~start.add:
            return True
        temp_true |= start.add & end.dele
        temp_false |= start.dele & end.add
        temp_num |= start.num_writes & end.num_writes
    if not (temp_true | temp_false | temp_num):
        return False
    return any(_reads(a, temp_true, temp_false, temp_num) for a in task.actions)


def _reads(action: GroundAction, true: int, false: int, num: int) -> bool:
    """Tell whether `action` reads one of the temporary facts or variables."""
    snaps = (action.start,) if action.end is None else (action.start, action.end)
    pos, neg = action.inv, action.inv_neg
    reads_num = 0
    for snap in snaps:
        pos |= snap.pre
        neg |= snap.neg
        reads_num |= snap.num_reads
        for ce in snap.cond_effects:
            pos |= ce.pre
            neg |= ce.neg
    own = _own(action)
    return bool(
        (pos & true & ~own) or (neg & false & ~own) or (reads_num & num & ~_own_num(action))
    )


def _own(action: GroundAction) -> int:
    """Return the facts `action` itself makes temporary (its own reading is sequential)."""
    if action.end is None:
        return 0
    return (action.start.add & action.end.dele) | (action.start.dele & action.end.add)


def _own_num(action: GroundAction) -> int:
    if action.end is None:
        return 0
    return action.start.num_writes & action.end.num_writes
