"""Table I as markdown: moves and mission time per situation, verdicts, a summary.

Rendered from the runs and bounds alone (what the CSVs hold), with fixed decimals and
no wall time, so the same CSVs give the same text byte for byte.
"""

from __future__ import annotations

from collections.abc import Sequence

from table1_bounds import BOUND_EXPANSIONS, Bound
from table1_model import PAPER, SITUATIONS, Run
from table1_stats import (
    BOOTSTRAP_RESAMPLES,
    BOOTSTRAP_SEED,
    LEVEL,
    MIN_PAIRS,
    Interval,
    Sample,
    describe,
)
from table1_summary import (
    ONLINE_BETTER,
    ONLINE_FASTER,
    Row,
    factors_of,
    rows_of,
    static_of,
)

__all__ = ["render_markdown", "summary_lines"]


def _num(value: float | None, digits: int = 1) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def _interval(interval: Interval | None) -> str:
    return "" if interval is None else f"[{interval.low:.1f}, {interval.high:.1f}]"


def _mean_sd_ci(sample: Sample) -> str:
    if sample.n == 0:
        return "n/a"
    return f"{_num(sample.mean)} ± {_num(sample.sd)} {_interval(sample.interval)}"


def _diff(sample: Sample) -> str:
    if sample.n == 0:
        return "n/a"
    return f"{sample.mean:+.1f} {_interval(sample.interval)} (n={sample.n})"


def _table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    return lines + ["| " + " | ".join(r) + " |" for r in rows]


def _speed_title(factor: float, runs: Sequence[Run]) -> str:
    speeds = sorted(
        {r.planning_speed for r in runs if r.task.factor == factor and r.planning_speed is not None}
    )
    absolute = (
        ", ".join(f"{s:g}" for s in speeds) + " expansions per simulated s"
        if speeds
        else "the agent file's own"
    )
    return f"planning speed x{factor:g} ({absolute})"


def _clairvoyant(row: Row) -> str:
    c = row.clairvoyant
    if c.n == 0 and row.clairvoyant_missing == 0:
        return "n/a"
    text = f"{_num(c.mean)} (n={c.n})" if c.n else "none found"
    return text + (
        f", {row.clairvoyant_missing} none found" if c.n and row.clairvoyant_missing else ""
    )


def moves_table(rows: Sequence[Row], static: Bound | None) -> list[str]:
    """Return the moves table of one planning speed."""
    head = [
        "situation (move,det,known)",
        "runs off/on",
        "failed off/on",
        "distinct traces off/on",
        "offline moves mean ± sd [95% CI]",
        "online moves mean ± sd [95% CI]",
        "online - offline [95% CI]",
        "verdict",
        "paper offline mu ± sigma",
        "paper online mu ± sigma",
        "paper mu+",
        "static optimum",
        "clairvoyant best found",
    ]
    body = []
    for r in rows:
        off, on = PAPER[r.situation]
        body.append(
            [
                r.situation.label,
                f"{r.offline.runs}/{r.online.runs}",
                f"{r.offline.failed}/{r.online.failed}",
                f"{r.offline.traces}/{r.online.traces}",
                _mean_sd_ci(r.offline.moves),
                _mean_sd_ci(r.online.moves),
                _diff(r.moves_diff),
                r.moves_verdict,
                f"{off.mu:.1f} ± {off.sigma:.1f}",
                f"{on.mu:.1f} ± {on.sigma:.1f}",
                f"{off.mu - on.mu:.1f}",
                "n/a" if static is None or static.moves is None else str(static.moves),
                _clairvoyant(r),
            ]
        )
    return _table(head, body)


def time_table(rows: Sequence[Row], static: Bound | None) -> list[str]:
    """Return the mission time table (simulated seconds) of one planning speed."""
    head = [
        "situation (move,det,known)",
        "offline time mean ± sd [95% CI]",
        "online time mean ± sd [95% CI]",
        "online - offline [95% CI]",
        "verdict",
        "static optimum makespan",
    ]
    best = "n/a" if static is None or static.makespan is None else _num(static.makespan)
    body = [
        [
            r.situation.label,
            _mean_sd_ci(r.offline.sim_time),
            _mean_sd_ci(r.online.sim_time),
            _diff(r.time_diff),
            r.time_verdict,
            best,
        ]
        for r in rows
    ]
    return _table(head, body)


def summary_lines(rows: Sequence[Row], runs: Sequence[Run] = ()) -> list[str]:
    """Say per planning speed in how many situations online wins on moves and on time,
    and how idle each mode's robot was (from `runs`, when given)."""
    out = []
    for factor in sorted({r.factor for r in rows}):
        mine = [r for r in rows if r.factor == factor]
        n = len(mine)
        moves = sum(r.moves_verdict == ONLINE_BETTER for r in mine)
        time = sum(r.time_verdict == ONLINE_FASTER for r in mine)
        moves_other = _other(mine, "moves_verdict")
        time_other = _other(mine, "time_verdict")
        out.append(
            f"- planning speed x{factor:g}: online is better on moves in {moves} of {n} "
            f"situations ({moves_other}); on mission time in {time} of {n} ({time_other})."
        )
        out += _idle_line(
            factor, [r for r in runs if r.task.clock == "lockstep" and r.task.factor == factor]
        )
    return out


def _idle_line(factor: float, runs: Sequence[Run]) -> list[str]:
    """The idle fraction (no action running) of each mode over the runs that recycled all."""
    idle = {
        m: [r.idle for r in runs if r.ok and r.task.mode == m and r.idle is not None]
        for m in ("offline", "online")
    }
    if not idle["offline"] or not idle["online"]:
        return []
    off, on = describe(idle["offline"]), describe(idle["online"])
    pairs = {
        m: {(r.task.situation, r.task.seed): r.idle for r in runs if r.ok and r.task.mode == m}
        for m in ("offline", "online")
    }
    both = sorted(set(pairs["offline"]) & set(pairs["online"]), key=str)
    diff = describe([(pairs["online"][k] or 0.0) - (pairs["offline"][k] or 0.0) for k in both])
    return [
        f"- planning speed x{factor:g}, idle (% of the mission with no action running): "
        f"offline {_mean_sd_ci(off)}, online {_mean_sd_ci(on)}; online - offline "
        f"{_diff(diff)} points."
    ]


def _other(rows: Sequence[Row], field: str) -> str:
    counts: dict[str, int] = {}
    for r in rows:
        v = getattr(r, field)
        key = "too few pairs" if v.startswith("too few pairs") else v
        counts[key] = counts.get(key, 0) + 1
    return ", ".join(f"{k}: {counts[k]}" for k in sorted(counts))


def failure_lines(rows: Sequence[Row]) -> list[str]:
    """List every failed run, by speed, situation, mode and seed."""
    out = []
    for r in rows:
        for mode, stats in (("offline", r.offline), ("online", r.online)):
            out += [f"- x{r.factor:g} {r.situation.label} {mode} {f}" for f in stats.failures]
    return out or ["- none"]


def realtime_table(runs: Sequence[Run]) -> list[str]:
    """Return the real-time runs (speed 1, no lockstep) beside the lockstep ones."""
    real = [r for r in runs if r.task.clock == "realtime"]
    if not real:
        return ["No real-time runs (`--no-realtime`)."]
    lock = {
        (r.task.situation, r.task.mode, r.task.seed): r
        for r in runs
        if r.task.clock == "lockstep" and r.task.factor == 1
    }
    by = {(r.task.situation, r.task.mode, r.task.seed): r for r in real}
    body = []
    for situation in SITUATIONS:
        for seed in sorted({r.task.seed for r in real if r.task.situation == situation}):
            cells = [situation.label, str(seed)]
            for mode in ("offline", "online"):
                run = by.get((situation, mode, seed))
                twin = lock.get((situation, mode, seed))
                cells += [
                    _run_cell(run),
                    "n/a" if twin is None or twin.moves is None else str(twin.moves),
                ]
            body.append(cells)
    fewer = 0
    for situation in SITUATIONS:
        means = [
            _mean([r.moves for r in real if r.task.situation == situation and r.task.mode == m])
            for m in ("offline", "online")
        ]
        fewer += means[0] is not None and means[1] is not None and means[1] < means[0]
    count = len({r.task.situation for r in real})
    said = [
        f"Online fewer moves than offline in real time (the mean of its runs): {fewer} of "
        f"{count} situations.",
        "",
    ]
    head = [
        "situation",
        "seed",
        "offline real time: moves, sim s (result)",
        "offline lockstep moves",
        "online real time: moves, sim s (result)",
        "online lockstep moves",
    ]
    return said + _table(head, body)


def _mean(values: Sequence[int | None]) -> float | None:
    """The mean of the runs that ended with a count (None if none did)."""
    done = [v for v in values if v is not None]
    return sum(done) / len(done) if done else None


def _run_cell(run: Run | None) -> str:
    if run is None:
        return "n/a"
    if run.moves is None:
        return run.result
    return f"{run.moves}, {_num(run.sim_time)} ({run.result})"


def _header(runs: Sequence[Run], bounds: Sequence[Bound]) -> list[str]:
    lock = [r for r in runs if r.task.clock == "lockstep"]
    seeds = sorted({r.task.seed for r in lock})
    up_args = sorted({r.up_args for r in runs if r.up_args})
    static = static_of(bounds)
    lines = [
        "# Table I: offline (plan, then act) against online (continual) planning",
        "",
        f"{len(lock)} lockstep runs ({_pace(lock)}): seeds {_seeds(seeds)}, planning speed factors "
        f"{', '.join(f'x{f:g}' for f in factors_of(lock))}; world options passed through: "
        + (", ".join(f"`{a}`" for a in up_args) if up_args else "none")
        + ".",
        "",
        "Statistics are over the runs that recycled every item (`done`); a run that did not "
        "is counted under *failed*, listed below, and never averaged. Intervals: "
        f"{LEVEL:.0%} percentile bootstrap of the mean ({BOOTSTRAP_RESAMPLES} resamples, "
        f"numpy seed {BOOTSTRAP_SEED}); *online - offline* pairs runs by seed. A verdict "
        f"needs the paired interval to exclude zero and at least {MIN_PAIRS} pairs. The "
        "paper's mu and sigma are over its 4 runs; its mu+ is offline mu - online mu. "
        "*Distinct traces* counts different world request traces (equal traces, equal "
        "runs): seeds that only reseed a deterministic world give one.",
        "",
    ]
    if static is None or static.moves is None:
        reason = f" ({static.status})" if static is not None else ""
        lines.append(f"Static optimum: not computed{reason}.")
    else:
        lines.append(
            f"Static optimum (every item known, no people; `cbdi plan --anytime`, "
            f"{static.timeout:g} s, {static.status}): {static.moves} moves, makespan "
            f"{_num(static.makespan)}."
        )
    lines.append(_clairvoyant_note(bounds))
    return [*lines, ""]


def _pace(runs: Sequence[Run]) -> str:
    speeds = sorted({r.speed for r in runs if r.speed is not None})
    named = [f"speed {s:g}" + (" (flat out)" if s == 0 else "") for s in speeds]
    if any(r.speed is None for r in runs):
        named.append("the scenario's speed")
    return ", ".join(named) or "no runs"


def stall_lines(runs: Sequence[Run]) -> list[str]:
    """List the runs in which a lockstep member missed its ack timeout."""
    out = [
        f"- {r.task.describe()}: {r.stalls} stalled epochs"
        for r in sorted(runs, key=lambda r: r.task.sort_key())
        if r.stalls
    ]
    return out or ["- none"]


def _clairvoyant_note(bounds: Sequence[Bound]) -> str:
    clair = [b for b in bounds if b.kind == "clairvoyant"]
    skipped = [b for b in clair if b.status == "skipped"]
    if skipped:
        return f"Clairvoyant column left out: {skipped[0].note}."
    if not clair:
        return "Clairvoyant column not computed."
    horizon = clair[0].horizon
    outlasting = sum(1 for b in clair if b.note)
    return (
        "Clairvoyant best found: every item known and the people's walk given as timed "
        f"initial literals ({horizon} epochs of the world core built from each run's own "
        "`cbdi up` flags, the robot standing still); the moves of the shortest-makespan plan "
        f"`cbdi plan --anytime` found within {BOUND_EXPANSIONS} node expansions (the same "
        "on any machine), "
        "averaged over the row's seeds: a best found, not an optimum."
        + (f" {outlasting} plans outlast the horizon." if outlasting else "")
    )


def _seeds(seeds: Sequence[int]) -> str:
    if seeds and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}..{seeds[-1]}" if len(seeds) > 1 else str(seeds[0])
    return ", ".join(map(str, seeds)) or "none"


def render_markdown(runs: Sequence[Run], bounds: Sequence[Bound]) -> str:
    """Return the whole markdown report of the runs and bounds."""
    rows = rows_of(runs, bounds)
    static = static_of(bounds)
    lines = _header(runs, bounds)
    for factor in sorted({r.factor for r in rows}):
        mine = [r for r in rows if r.factor == factor]
        title = _speed_title(factor, runs)
        lines += [f"## Moves, {title}", "", *moves_table(mine, static), ""]
        lines += [f"## Mission time (simulated s), {title}", "", *time_table(mine, static), ""]
    lines += ["## Summary", "", *summary_lines(rows, runs), ""]
    lines += ["## Failed runs", "", *failure_lines(rows), ""]
    lines += ["## Lockstep stalls (an ack timeout: the run may hang on timing)", ""]
    lines += [*stall_lines(runs), ""]
    lines += ["## Real time (`--speed 1 --no-lockstep`), planning speed x1", ""]
    lines += [*realtime_table(runs), ""]
    return "\n".join(lines)
