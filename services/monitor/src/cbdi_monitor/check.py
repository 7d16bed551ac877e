"""`cbdi replay FILE --agent A --check`: one agent's decisions, made again from its inputs.

The agent's planner and scheduler are built by their own packages, through the
`cbdi.shells` entry-point group (the monitor imports no service), from the arguments the
launcher recorded, and run in this process on the in-memory bus (`cbdi.runtime.together`)
with the world's info served from the recording and a stand-in for every other sender
playing the recording's script (`cbdi_monitor.reenact`). What they publish is then
compared with what the originals published (`cbdi_monitor.difference`). Exit 0: all the
same; 1: a difference (the first one is named) or a replay that stalled; 2: bad usage or
a recording that cannot be replayed.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any

from cbdi import keys
from cbdi.bus import LogSink, MemoryNetwork, messages
from cbdi.bus.base import Bus
from cbdi.clock import Clock, WallClock
from cbdi.errors import CbdiError
from cbdi.runtime.host import SHELLS
from cbdi.runtime.together import Together, TogetherService
from cbdi.wire.world import EpochAck
from cbdi_monitor.difference import WHEN, Difference, Verdict
from cbdi_monitor.errors import NoShellError
from cbdi_monitor.reenact import (
    REPLAYED,
    AgentScript,
    Ask,
    Await,
    Output,
    Send,
    outputs_of,
    sender_of,
    shell_args,
)

__all__ = ["Replayed", "describe", "load_shells", "reenact", "report"]

# After the script, the replay is over once the network was quiet for QUIET wall seconds
# with the members having published at least as many messages as recorded, or for
# STRAGGLE seconds with fewer (a planner round may still be running in its thread).
QUIET, STRAGGLE = 0.5, 5.0
# The rebuilt services log errors only: once a replay differs, the recorded inputs no
# longer fit what they decided, and every one of them would be a warning.
LOG_LEVEL = "error"


@dataclass
class Replayed:
    """What the rebuilt members published, how they ended, and whether the replay stalled."""

    outputs: dict[str, list[Output]] = field(default_factory=dict)
    exit_codes: dict[str, int] = field(default_factory=dict)
    stalled: str = ""


def load_shells(
    script: AgentScript, agent_file: str, path: str
) -> tuple[list[TogetherService], list[str]]:
    """Build the agent's planner and scheduler; return them and how each was built.

    Raise NoShellError if no installed package builds a component, and the shell's own
    error (CbdiError, ValueError) on a bad agent file or setting.
    """
    found = {ep.name: ep for ep in entry_points(group=SHELLS)}
    services, sources = [], []
    for component in REPLAYED:
        ep = found.get(component)
        if ep is None:
            raise NoShellError(
                f"no installed package builds a {component} (entry-point group {SHELLS}; "
                f"install cbdi-{component})"
            )
        args, source = shell_args(script, component, agent_file, path)
        build: Callable[[list[str]], TogetherService] = ep.load()
        service = build(args)
        services.append(service)
        sources.append(f"{service.service}: {' '.join(args)} ({source})")
    return services, sources


class _Acks:
    """The acks the rebuilt members sent so far, to wait for one of them."""

    def __init__(self) -> None:
        self.seen: set[tuple[str, int, str]] = set()
        self.changed = asyncio.Condition()

    async def follow(self, stream: AsyncIterator[tuple[str, EpochAck]]) -> None:
        async for _, ack in stream:
            async with self.changed:
                self.seen.add((keys.member(ack.agent, ack.component), ack.epoch, ack.stage))
                self.changed.notify_all()

    async def wait(self, step: Await, timeout: float) -> bool:
        """Wait for the ack `step` names; False if it did not come within `timeout` s."""
        wanted = (step.member, step.epoch, step.stage)
        try:
            async with asyncio.timeout(timeout), self.changed:
                await self.changed.wait_for(lambda: wanted in self.seen)
        except TimeoutError:
            return False
        return True


async def reenact(
    script: AgentScript,
    services: list[TogetherService],
    timeout: float,
    clock: Clock | None = None,
) -> Replayed:
    """Run the rebuilt members against the script's stand-ins; return what they published."""
    clock = clock or WallClock()
    network = MemoryNetwork()
    together = Together(services, network, log_level=LOG_LEVEL)
    acks = _Acks()
    replayed = Replayed()

    async def serve_info(key: str, payload: bytes) -> bytes:
        return script.info

    async def play() -> None:
        try:
            replayed.stalled = await _play(script, network, acks, timeout)
            expected = sum(len(outputs) for outputs in script.outputs.values())
            await _quiet(network, script.members, expected, clock)
        finally:
            together.stop()

    acked = messages(network.bus(), keys.epoch_ack(script.agent, "*"), EpochAck, LogSink())
    async with asyncio.TaskGroup() as tg:
        helpers = [
            tg.create_task(network.bus().serve(keys.world_rpc("info"), serve_info)),
            tg.create_task(acks.follow(acked)),
        ]
        tg.create_task(play())
        replayed.exit_codes = await together.run()
        for helper in helpers:
            helper.cancel()
    published = ((s.key, s.seq, s.payload) for s in network.published)
    replayed.outputs = outputs_of(published, script.members)
    return replayed


async def _play(script: AgentScript, network: MemoryNetwork, acks: _Acks, timeout: float) -> str:
    """Send the stand-ins' messages, waiting for the members' acks between them; return
    why the replay stalled ("" if it did not)."""
    standins: dict[str, Bus] = {}
    for step in script.steps:
        if isinstance(step, Send):
            bus = standins.get(step.sender) or standins.setdefault(step.sender, network.bus())
            await bus.publish(step.key, step.payload, block=True)
        elif isinstance(step, Ask):
            asker = standins.get("asker") or standins.setdefault("asker", network.bus())
            try:
                await asker.request(step.key, step.payload, timeout=timeout)
            except CbdiError as exc:
                return f"the request on {step.key} was not answered: {exc}"
        elif not await acks.wait(step, timeout):
            what = "start (ready)" if step.epoch < 0 else f"epoch {step.epoch} ({step.stage})"
            return f"{step.member} did not acknowledge its {what} within {timeout:g} s"
    return ""


async def _quiet(network: MemoryNetwork, members: list[str], expected: int, clock: Clock) -> None:
    """Let the members finish what the last inputs set off (see `QUIET`): `expected` is
    how many compared messages they published in the recording."""
    seen = ours = 0  # publications looked at; the members' among them
    since = clock.now()
    while True:
        new = network.published[seen:]
        seen += len(new)
        ours += sum(1 for s in new if sender_of(s.key) in members)
        if new:
            since = clock.now()
        if clock.now() - since >= (QUIET if ours >= expected else STRAGGLE):
            return
        await clock.sleep(QUIET / 10)


def report(script: AgentScript, verdict: Verdict, replayed: Replayed, seconds: float) -> list[str]:
    """Return the lines saying how the replay went (the first difference, if any)."""
    lines = [f"note: {n}" for n in script.notes]
    if replayed.stalled:
        lines.append(f"stalled: {replayed.stalled}")
    lines += [f"{s} exited {c}" for s, c in sorted(replayed.exit_codes.items()) if c != 0]
    if verdict.first is not None:
        lines += describe(verdict.first)
    who = f"{script.agent}'s {' and '.join(REPLAYED)}"
    extra = f", {verdict.unverified} not in the file" if verdict.unverified else ""
    if verdict.same:
        lines.append(
            f"same: {verdict.matched} messages of {who} on {verdict.keys} keys match, "
            f"epochs 0 to {script.last_epoch}{extra} (replayed in {seconds:.1f} s)"
        )
    else:
        lines.append(
            f"differs: {verdict.differing} messages of {who} differ, {verdict.matched} match"
            f"{extra} (replayed in {seconds:.1f} s)"
        )
    return lines


def describe(d: Difference) -> list[str]:
    """Name a difference: key, index and sequence number, epoch, member and stage, fields."""
    stage = f"stage {d.stage}" if d.stage else "after its last ack"
    when = f"epoch {d.epoch}"
    if d.kind == "differs" and d.recorded_epoch != d.epoch:
        when += f" (recorded in epoch {d.recorded_epoch})"
    head = f"first difference: {d.key} #{d.index} (seq {d.seq}), {when}, {d.member} {stage}"
    if d.kind == "missing":
        return [f"{head}: recorded, not replayed", f"  recorded: {_short(d.message)}"]
    if d.kind == "extra":
        return [f"{head}: replayed, not recorded", f"  replayed: {_short(d.message)}"]
    lines = [head]
    for f in d.fields:
        lines.append(f"  {f.path}: recorded {_short(f.recorded)}, replayed {_short(f.replayed)}")
    if all(f.path == WHEN for f in d.fields):
        lines.append(f"  message: {_short(d.message)}")
    return lines


def _short(value: Any, limit: int = 160) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
