"""The fleet benchmark's markdown table and figure (`fleet.py`)."""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import fleet_bound
from table1_stats import Sample, describe

if TYPE_CHECKING:
    from fleet import FleetRun
    from fleet_bound import Bound

__all__ = ["draw", "markdown"]


def _mean(sample: Sample, digits: int = 1) -> str:
    if sample.mean is None:
        return "-"
    text = f"{sample.mean:.{digits}f}"
    if sample.n > 1 and sample.sd is not None and sample.interval is not None:
        i = sample.interval
        text += f" ± {sample.sd:.{digits}f} [{i.low:.{digits}f}, {i.high:.{digits}f}]"
    return text


def _ratio(values: Sequence[float], digits: int = 2) -> str:
    return f"{statistics.fmean(values):.{digits}f}" if values else "-"


def markdown(
    runs: Sequence[FleetRun],
    bounds: dict[tuple[str, int], Bound | None],
    maps: Sequence[str],
    sizes: Sequence[int],
) -> str:
    """The table of every map and fleet size, and how the bound is derived."""
    out = [
        "# Fleet benchmark",
        "",
        "Lockstep runs (`cbdi up SCENARIO --agents N --seed S --speed 0 --until done`, "
        "by default with `--option people_phase=true --option people_jitter=1`: the seed "
        "sets where each person starts on its loop and jitters their pace), seeds 1..n. "
        "Mission time in simulated seconds: mean ± standard deviation "
        "[95% bootstrap interval of the mean], over runs that ended `done`. "
        "*bound*: the lower bound below (its deciding term); *x bound*: mean mission time "
        "over the bound; *speed-up*: the mean mission time of 1 robot over this one's. "
        "*busy*: each robot's simulated seconds in actions over the mission time, the "
        "least and the mean over robots and runs. *searches/action*: plans published "
        "(fresh, repair, revised goal, improvement) per action asked of the world. "
        "*claim changes/item*: times an item's owner (as every robot's scheduler assigns "
        "it from the group's claims) became another robot from one epoch to the next, "
        "per item.",
        "",
    ]
    restarted = [r for r in runs if r.restarts]
    if restarted:
        out += [
            f"**{len(restarted)} of {len(runs)} runs had services restarted** (the freeze "
            "watchdog on a machine short of CPU, or a crash), so they are not a function "
            "of their inputs alone: "
            + ", ".join(f"{r.scenario} x{r.agents} seed {r.seed}" for r in restarted)
            + ".",
            "",
        ]
    stalled = [r for r in runs if r.stalls and not r.restarts]
    if stalled:
        out += [
            f"**{len(stalled)} of {len(runs)} runs had lockstep members that missed the "
            "ack timeout** (the world went on without them, so what they sent was taken "
            "an epoch late and the run depends on the machine's load): "
            + ", ".join(f"{r.scenario} x{r.agents} seed {r.seed}" for r in stalled)
            + ".",
            "",
        ]
    for name in maps:
        out += [f"## {name}", ""]
        out.append(
            "| N | done | mission time (s) | bound (s) | x bound | speed-up | moves/item "
            "| busy min / mean | searches/action | claim changes/item | wall (s) |"
        )
        out.append("|---|---|---|---|---|---|---|---|---|---|---|")
        single: float | None = None
        for n in sizes:
            bound = bounds.get((name, n))
            mine = [r for r in runs if r.scenario == name and r.agents == n]
            if bound is None:
                out.append(f"| {n} | the map has fewer start cells | | | | | | | | | |")
                continue
            done = [r for r in mine if r.mission_time is not None]
            times = describe([r.mission_time for r in done if r.mission_time is not None])
            if n == 1 and times.mean is not None:
                single = times.mean
            busy = [b for r in done for b in r.busy_fractions]
            least = [min(r.busy_fractions) for r in done if r.busy_fractions]
            speedup = f"{single / times.mean:.2f}" if single is not None and times.mean else "-"
            x_bound = f"{times.mean / bound.value:.2f}" if times.mean else "-"
            out.append(
                f"| {n} | {len(done)}/{len(mine)} | {_mean(times)} "
                f"| {bound.value:.1f} ({bound.term}) | {x_bound} | {speedup} "
                f"| {_ratio([r.moves / r.recycled for r in done if r.recycled], 1)} "
                f"| {_ratio(least)} / {_ratio(busy)} "
                f"| {_ratio([r.searches / r.actions for r in done if r.actions])} "
                f"| {_ratio([r.claim_changes / r.items for r in done if r.items])} "
                f"| {_ratio([r.wall for r in mine], 0)} |"
            )
        failed = [r for r in runs if r.scenario == name and r.mission_time is None]
        for r in failed:
            out.append(f"\n- N={r.agents} seed {r.seed}: {r.result} ({r.reason or r.exit})")
        out.append("")
    out += ["## The lower bound", "", (fleet_bound.__doc__ or "").strip(), ""]
    return "\n".join(out)


def draw(
    runs: Sequence[FleetRun],
    bounds: dict[tuple[str, int], Bound | None],
    maps: Sequence[str],
    sizes: Sequence[int],
    path: Path,
) -> None:
    """Mission time against fleet size per map (means, 95% intervals) and the bound."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(maps), figsize=(5.5 * len(maps), 4), squeeze=False)
    for ax, name in zip(axes[0], maps, strict=True):
        xs, means, lows, highs, bx, by = [], [], [], [], [], []
        for n in sizes:
            bound = bounds.get((name, n))
            if bound is None:
                continue
            bx.append(n)
            by.append(bound.value)
            sample = describe(
                [
                    r.mission_time
                    for r in runs
                    if r.scenario == name and r.agents == n and r.mission_time is not None
                ]
            )
            if sample.mean is None:
                continue
            xs.append(n)
            means.append(sample.mean)
            interval = sample.interval
            lows.append(sample.mean - (interval.low if interval else sample.mean))
            highs.append((interval.high if interval else sample.mean) - sample.mean)
        ax.errorbar(xs, means, yerr=[lows, highs], fmt="o-", capsize=4, label="mission time")
        ax.plot(bx, by, "k--", label="lower bound")
        ax.set_xscale("log", base=2)
        ax.set_xticks(bx, [str(n) for n in bx])
        ax.set_xlabel("robots")
        ax.set_ylabel("simulated seconds")
        ax.set_title(name)
        ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
