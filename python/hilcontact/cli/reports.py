"""The console reports of the ``hilcontact`` commands: a run's collision table, a
comparison, a sweep, the real-time live lines and summaries, `check`'s report."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table

if TYPE_CHECKING:
    from ..comparison import Comparison
    from ..run import Run


def _number(value: Any, fmt: str, scale: float = 1.0) -> str:
    if value is None:
        return "-"
    try:
        number = float(value) * scale
    except (TypeError, ValueError):
        return "-"
    return format(number, fmt) if math.isfinite(number) else "-"


def _report(console: Console, result: Run, folder: Path) -> None:
    delay_ms = result.scenario.facility.robot_delay * 1e3
    table = Table(
        title=f"{result.scenario.name}: compensator {result.compensator}, robot delay {delay_ms:g} ms",
        pad_edge=False,
    )
    # two-line headers, numbers never wrapped: fits 80 columns
    for header in ("#", "start\n(s)", "end\n(s)", "CoV", "CoF", "v err\n(%)", "peak\nF (N)",
                   "rebound\n(mm/s)", "ideal\n(mm/s)"):
        table.add_column(header, justify="right", no_wrap=True)
    for number, row in result.collision_table().iterrows():
        table.add_row(
            str(number) if row["complete"] else f"{number}*",
            _number(row["start"], ".3f"),
            _number(row["end"], ".3f"),
            _number(row["cov"], ".3f"),
            _number(row["cof"], ".3f"),
            _number(row["velocity_error"], ".1f", 1e2),
            _number(row["peak_force"], ".1f"),
            _number(row["rebound_speed"], ".2f", 1e3),
            _number(row["reference_rebound_speed"], ".2f", 1e3),
        )
    if table.row_count:
        console.print(table)
        from ..plots import shows_episodes

        if shows_episodes(result):  # not for a 1-D frictionless run: nothing but J_n to add
            console.print(_episode_table(result))
        if not result.collision_table()["complete"].all():
            console.print("*: still under way at the end of the run (no rebound, not compared)")
        rendered = _rendered_by(result)
        if rendered:
            console.print(f"rendered by: {escape(rendered)}", soft_wrap=True)
    else:
        console.print("no collisions")
    if result.status == "ok":
        console.print("status: [green]ok[/green]")
    elif result.status == "unfaithful":
        violations = result.metrics.get("violations") or []
        console.print("[bold yellow]status: unfaithful[/bold yellow] (tolerances in the scenario's \\[metrics])")
        for line in violations:
            console.print(f"  [yellow]{escape(str(line))}[/yellow]", soft_wrap=True)
    else:
        at = result.metrics.get("diverged_at")
        when = f" at {at:.3f} s" if isinstance(at, (int, float)) else ""
        reason = result.metrics.get("reason") or "no reason given"
        console.print(
            f"[bold red]status: {escape(result.status)}{when}: {escape(str(reason))}[/bold red]", soft_wrap=True
        )
    files = ", ".join(sorted(p.name for p in folder.iterdir()))
    console.print(f"saved to {escape(str(folder))}/ ({escape(files)})", soft_wrap=True)


def _rendered_by(result: Run) -> str:
    """How the collisions were handled, runs of the same grouped ("1-2 pida: no prior, 3-5
    model"); empty for a compensator that does not report it (any but model-mediated)."""
    table = result.collision_table()
    if not (table["rendering"] != "-").any():
        return ""
    groups: list[list[Any]] = []  # [first, last, label]
    for number, label in table["rendering"].items():
        if groups and groups[-1][2] == label and groups[-1][1] == number - 1:
            groups[-1][1] = number
        else:
            groups.append([number, number, label])
    return ", ".join(f"{a} {label}" if a == b else f"{a}-{b} {label}" for a, b, label in groups)


def _episode_table(result: Run) -> Table:
    """The contact of each episode (the collision table's episode columns, docs/model.md
    "Metrics"): normal and tangential impulse, their errors, the rebound direction and
    angular velocity errors, the peak moment about the sensor origin."""
    table = Table(title="contact episodes (errors against the ideal reference)", pad_edge=False)
    for header in ("#", "J_n\n(N·s)", "J_t\n(N·s)", "J_n err\n(%)", "J_t err\n(%)", "dir err\n(°)",
                   "ω err\n(%)", "peak M\n(N·m)"):
        table.add_column(header, justify="right", no_wrap=True)
    for number, row in result.collision_table().iterrows():
        table.add_row(
            str(number) if row["complete"] else f"{number}*",
            _number(row["normal_impulse"], ".4g"),
            _number(row["tangential_impulse"], ".4g"),
            _number(row["normal_impulse_error"], ".2f", 1e2),
            _number(row["tangential_impulse_error"], ".2f", 1e2),
            _number(row["direction_error"], ".2f"),
            _number(row["angular_velocity_error"], ".1f", 1e2),
            _number(row["peak_moment"], ".3g"),
        )
    return table


def _report_mcap(console: Console, recorded: dict[str, Any] | None) -> None:
    """One line on the run's MCAP file (and its write errors, if any)."""
    if not recorded:
        return
    line = (
        f"mcap: {escape(str(recorded.get('path')))} ({recorded.get('messages')} messages in "
        f"{recorded.get('chunks')} chunks, {_number(recorded.get('bytes'), '.1f', 1e-6)} MB)"
    )
    if recorded.get("write_errors") or not recorded.get("complete"):
        line += (
            f" [bold yellow]incomplete: {recorded.get('write_errors')} write errors: "
            f"{escape(str(recorded.get('error')))}[/bold yellow]"
        )
    console.print(line, soft_wrap=True)


def _report_comparison(console: Console, result: Comparison, folder: Path) -> None:
    """`hilcontact compare`'s report: a row per compensator (compared order) with its rank,
    then the tolerance each unfaithful one broke, the ranking and the recommendation. Fits 80
    columns: the CoV cell wraps between numbers, never inside one."""
    s = result.scenario
    table = Table(
        title=f"{s.name}: robot delay {s.facility.robot_delay * 1e3:g} ms, "
        f"sensor delay {s.facility.sensor_delay * 1e3:g} ms",
        pad_edge=False,
    )
    summary = result.summary
    covs = {kind: [_number(v, ".2f") for v in row["cov"]] for kind, row in summary.iterrows()}
    longest = max((len(text) for texts in covs.values() for text in texts), default=1)
    table.add_column("compensator", no_wrap=True)
    table.add_column("status", min_width=10)
    # two CoVs a line, wrapped between numbers only
    table.add_column("CoV of\n#1, #2 …", min_width=max(longest, 4), max_width=max(2 * longest + 1, 9))
    for header in ("worst\nCoF", "v err\n%", "dir\nerr °", "J_t\nerr %", "k err\n%", "c err\nN·s/mm"):
        table.add_column(header, justify="right", no_wrap=True)
    standings = {standing.kind: standing for standing in result.ranking}
    for kind, row in summary.iterrows():
        standing = standings[str(kind)]
        if row["status"] == "ok":
            status = "[green]ok[/green]"
        elif row["status"] == "unfaithful":
            status = "[yellow]unfaithful[/yellow]"
            if standing.faithful_from is not None:
                status = f"[yellow]ok from #{standing.faithful_from}[/yellow]"
        else:
            at = row["diverged_at"]
            when = f" {at:.2f} s" if math.isfinite(at) else ""
            status = f"[bold red]{escape(str(row['status']))}{when}[/bold red]"
        table.add_row(
            escape(str(kind)),
            status,
            " ".join(covs[kind]) or "-",
            _number(row["worst_cof"], ".3f"),
            _number(row["worst_velocity_error_pct"], ".1f"),
            _number(row["worst_direction_error_deg"], ".1f"),
            _number(row["worst_tangential_impulse_error_pct"], ".1f"),
            _number(row["stiffness_error_pct"], ".3g"),
            _number(row["damping_error_Ns_mm"], ".3g"),
        )
    console.print(table)
    console.print(
        "CoV, CoF: rebound speed and peak force / ideal reference (1 is perfect); v err, dir err: "
        "rebound velocity vector and direction errors; J_t err: tangential impulse error; "
        "ranked below (docs/choosing.md); mean CoV and worst |CoV-1| in comparison.md",
        soft_wrap=True,
    )
    for standing in result.ranking:
        if standing.reason:
            console.print(f"  {standing.rank}. {escape(standing.kind)}: {escape(standing.reason)}", soft_wrap=True)
    console.print(f"[bold]recommendation:[/bold] {escape(result.recommendation)}", soft_wrap=True)
    files = ", ".join(sorted(p.name + ("/" if p.is_dir() else "") for p in folder.iterdir()))
    console.print(f"saved to {escape(str(folder))}/ ({escape(files)})", soft_wrap=True)


def _report_sweep(console: Console, rows: Any, out: str) -> None:
    from ..stability import faithful

    table = Table(title=f"sweep: {len(rows)} runs")
    for header in ("compensator", "runs", "ok", "unfaithful", "diverged", "faithful", "median wall time (ms)"):
        table.add_column(header, justify="right" if header != "compensator" else "left")
    marks = faithful(rows)
    for kind, group in rows.groupby("compensator", sort=False):
        ok = int((group["status"] == "ok").sum())
        unfaithful = int((group["status"] == "unfaithful").sum())
        table.add_row(
            escape(str(kind)),
            str(len(group)),
            str(ok),
            str(unfaithful),
            str(len(group) - ok - unfaithful),
            f"{int(marks[group.index].sum())}",
            _number(group["wall_time"].median(), ".2f", 1e3),
        )
    console.print(table)
    console.print(
        "ok: faithful within the scenario's [metrics] tolerances (default |CoV-1| <= 5 %, CoF <= 1.2, "
        "rebound velocity error <= 5 %, no lost or extra collision); faithful: ok with a compared "
        "collision (see hilcontact stability-map)",
        soft_wrap=True,
    )
    console.print(f"saved to {escape(out)}/results.parquet", soft_wrap=True)



def _report_stability_map(console: Console, result: Any, folder: Path, criterion: str, files: Sequence[str]) -> None:
    """`hilcontact stability-map`'s tables: the faithful runs of each cell (compensator and
    contact frequency down, robot delay across; ✓: faithful by the map's cell rule), then the
    maximal faithful robot delay (ms) per contact frequency and compensator, then the files."""
    cells = result.cells
    delays = sorted(cells["robot_delay"].unique())
    if 30 + 7 * len(delays) > console.width:  # too many delays for a grid: the mixed cells only
        mixed = cells[(cells["faithful_runs"] > 0) & (cells["faithful_runs"] < cells["runs"])]
        console.print(f"faithful runs per cell: {len(delays)} delays, see stability_map.png and cells.csv; "
                      f"cells where only some runs are faithful: {len(mixed)}", soft_wrap=True)
        for _, cell in mixed.iterrows():
            mark = " ✓" if cell["faithful"] else ""
            console.print(f"  {escape(str(cell['compensator']))}, {cell['contact_frequency']:.2f} Hz, "
                          f"{cell['robot_delay'] * 1e3:g} ms: {int(cell['faithful_runs'])}/{int(cell['runs'])}{mark}",
                          soft_wrap=True)
        console.print(f"a run is faithful with {criterion}; ✓: {result.rule}", soft_wrap=True)
    else:
        _cell_grid(console, cells, delays, criterion, result.rule)
    best = result.max_faithful_delay()
    table = Table(title=f"maximal faithful robot delay (ms): {criterion}")
    table.add_column("contact frequency (Hz)", justify="right")
    for kind in best.columns:
        table.add_column(escape(str(kind)), justify="right")
    for freq, row in best.iterrows():
        table.add_row(_number(freq, ".2f"), *(_number(v, "g", 1e3) for v in row))
    console.print(table)
    console.print("- : not faithful even at the smallest swept delay", soft_wrap=True)
    console.print(f"saved to {escape(str(folder))}/ ({', '.join(files)})", soft_wrap=True)


def _cell_grid(console: Console, cells: Any, delays: list[float], criterion: str, rule: str) -> None:
    """The faithful runs of every cell: compensator and frequency down, delay across."""
    grid = Table(title="faithful runs per cell", padding=(0, 1))
    grid.add_column("compensator", no_wrap=True)
    grid.add_column("Hz", justify="right", no_wrap=True)
    for delay in delays:
        grid.add_column(f"{delay * 1e3:g} ms", justify="right", no_wrap=True)
    for (kind, freq), group in cells.groupby(["compensator", "contact_frequency"], sort=False):
        by_delay = group.set_index("robot_delay")
        row = []
        for delay in delays:
            if delay not in by_delay.index:
                row.append("")
                continue
            cell = by_delay.loc[delay]
            mark = "[green]✓[/green]" if cell["faithful"] else " "
            row.append(f"{int(cell['faithful_runs'])}/{int(cell['runs'])}{mark}")
        grid.add_row(escape(str(kind)), _number(freq, ".2f"), *row)
    console.print(grid)
    console.print(f"a run is faithful with {criterion}; ✓: {rule}", soft_wrap=True)


def _report_identification(console: Console, log: str, collisions: Any) -> None:
    """`hilcontact identify`'s table: per collision, stiffness (N/mm) and damping (N s/mm) with
    their uncertainty, the wall's normal (± deg) and point (mm, ± mm), and the friction
    coefficient μ (± its standard error; '-' on a frictionless surface)."""
    table = Table(title=f"{log}: {len(collisions)} collision(s)")
    for name in ("#", "start s", "k N/mm", "c N·s/mm", "normal", "±deg", "point mm", "±mm", "μ"):
        table.add_column(name, justify="right")
    for _, c in collisions.iterrows():
        frictional = bool(c.get("frictional", False))
        mu = (f"{c['friction']:.3f} ± {c['friction_std']:.3f}"
              if frictional and c.get("sliding_samples", 0) >= 2 else ("slid too little" if frictional else "-"))
        table.add_row(
            str(int(c["index"])), f"{c['start']:.3f}",
            f"{c['stiffness'] / 1e3:.3f} ± {c['stiffness_std'] / 1e3:.3f}",
            f"{c['damping'] / 1e3:.4f} ± {c['damping_std'] / 1e3:.4f}",
            f"({c['normal_x']:.4f}, {c['normal_y']:.4f}, {c['normal_z']:.4f})", f"{c['normal_std_deg']:.3g}",
            f"({c['point_x'] * 1e3:.2f}, {c['point_y'] * 1e3:.2f}, {c['point_z'] * 1e3:.2f})", f"{c['offset_std'] * 1e3:.3g}",
            mu,
        )
    console.print(table)

def _hil_line(s: dict[str, Any]) -> str:
    return (
        f"{s['phase']}  t {s['time']:7.3f} s | F {s['force']:7.1f} N | E {s['energy'] * 1e3:8.3f} mJ | "
        f"latency max {s['max_latency_us']:.0f} µs, overruns {s['overruns']} | "
        f"sensor lost {s['sensor_lost']} late {s['sensor_late']} | robot lost {s['robot_lost']} late {s['robot_late']} | "
        f"dropped {s['dropped']}"
    )


def _facility_line(s: dict[str, Any]) -> str:
    sensor, robot = s.get("sensor_protocol", "RDT"), s.get("robot_protocol", "EGM")
    return (
        f"facility  t {s['time']:8.3f} s | contact {s['contact_force']:7.1f} N | {sensor} sent {s['sensor']['sent']} | "
        f"{robot} sent {s['robot']['sent']}, corrections {s['corrections']} (dropped {s['corrections_dropped']}) | "
        f"io errors {s.get('io_errors', 0)} | overruns {s['overruns']}"
    )


def _facility_errors(s: dict[str, Any]) -> str:
    """The emulator's socket errors per endpoint, for the summary after it stops."""
    parts = []
    for link in ("sensor", "robot"):
        stats = s.get(link) or {}
        parts.append(
            f"{link} ({s.get(link + '_protocol', '?')}): sent {stats.get('sent')}, send errors {stats.get('send_errors')}, "
            f"io errors {stats.get('io_errors')}, received {stats.get('received')}, dropped "
            f"{sum(stats.get(k, 0) for k in ('malformed', 'invalid', 'foreign', 'stale'))}"
        )
    return "; ".join(parts)


def _scheduling_line(s: dict[str, Any]) -> str:
    """One line of what the OS granted the loop thread (``metrics.json`` ``realtime.scheduling``):
    ``scheduling: SCHED_FIFO 80 granted, memory locked, not pinned``, with each refusal's reason."""
    if s.get("policy") == "fifo":
        parts = [f"SCHED_FIFO {s.get('priority')} " + ("granted" if s.get("fifo_granted") else "(inherited)")]
    elif s.get("policy") == "rr":
        parts = [f"SCHED_RR {s.get('priority')} (inherited)"]
    else:
        parts = ["normal priority"]
    parts.append("memory locked" if s.get("memory_locked") else "memory not locked")
    parts.append(f"pinned to CPU {s.get('cpu')}" if s.get("pinned") else "not pinned")
    line = "scheduling: " + ", ".join(parts)
    refused = s.get("refused") or []
    if refused:
        line += " (refused: " + "; ".join(refused) + ")"
    return line


def _report_realtime(console: Console, run: Run) -> None:
    rt = run.metrics.get("realtime") or {}
    timing = rt.get("timing", {})
    lat, per, comp = (timing.get(k, {}) for k in ("wake_latency_us", "period_error_us", "compute_us"))
    sensor, robot = rt.get("sensor", {}), rt.get("robot", {})
    console.print(
        f"loop: {rt.get('ticks')} ticks at {1.0 / rt.get('period', 1.0):g} Hz in {rt.get('wall_time', 0.0):.3f} s; "
        f"wake latency p50/p99/max {lat.get('p50', 0):.0f}/{lat.get('p99', 0):.0f}/{lat.get('max', 0):.0f} µs; "
        f"period jitter p50/p99/max {per.get('p50', 0):.0f}/{per.get('p99', 0):.0f}/{per.get('max', 0):.0f} µs; "
        f"compute p99 {comp.get('p99', 0):.0f} µs; overruns {timing.get('overruns')}",
        soft_wrap=True,
    )
    if rt.get("scheduling"):
        console.print(_scheduling_line(rt["scheduling"]), soft_wrap=True)
    kinds = {k: str((rt.get("options", {}).get(k) or {}).get("kind", d)).upper() for k, d in (("sensor", "rdt"), ("robot", "egm"))}
    for name, link in ((f"sensor ({kinds['sensor']})", sensor), (f"robot ({kinds['robot']})", robot)):
        console.print(
            f"{name}: received {link.get('received')}, accepted {link.get('accepted')}, lost {link.get('lost')}, "
            f"late {link.get('late')}, malformed {link.get('malformed')}, invalid {link.get('invalid')}, "
            f"foreign {link.get('foreign')}, stale {link.get('stale')}",
            soft_wrap=True,
        )
    for text, warning in _identification_lines(run):
        console.print(("[yellow]warning:[/yellow] " if warning else "") + escape(text), soft_wrap=True)
    if rsi := rt.get("rsi"):
        ans = rsi.get("answer_latency_us", {})
        console.print(
            f"RSI answers: latency p50/p99/max {ans.get('p50', 0):.0f}/{ans.get('p99', 0):.0f}/{ans.get('max', 0):.0f} µs, "
            f"late (> {rsi.get('deadline_us', 0):.0f} µs) {rsi.get('answers_late')}, unanswered {rsi.get('unanswered')}",
            soft_wrap=True,
        )


#: The identification of a real-time run is said to drift beyond these: a mean stiffness error
#: of 2 % (simulations stay below 0.2 %, docs/identification.md) or a mean damping error of
#: 50 N·s/m (noisy simulations stay below 13).
IDENTIFICATION_DRIFT = (0.02, 50.0)


def _identification_lines(run: Run) -> list[tuple[str, bool]]:
    """The summary's identification: k̂ and ĉ at the last contact tick, their mean errors
    against the scenario (metrics.json's ``identification``), and a warning when they drift
    (:data:`IDENTIFICATION_DRIFT`), naming the stale sensor records if there were many."""
    import numpy as np

    ident = run.metrics.get("identification")
    series = run.timeseries
    if not ident or "stiffness_estimate" not in series.columns:
        return []
    force = np.linalg.norm(series[[f"measured_force_{a}" for a in "xyz"]].to_numpy(dtype=float), axis=1)
    k_hat, c_hat = series["stiffness_estimate"].to_numpy(dtype=float), series["damping_estimate"].to_numpy(dtype=float)
    contact = np.flatnonzero((force > 3.0) & np.isfinite(k_hat))
    if len(contact) == 0:
        return []
    last = contact[-1]
    k, c = float(run.scenario.contact.stiffness), float(run.scenario.contact.damping)
    k_err, c_err = ident.get("stiffness_error"), ident.get("damping_error")
    online = _online_identification(run)
    spread = (f" (± {online['stiffness_std'] / 1e3:.2f}, ± {online['damping_std'] / 1e3:.3f}: 1σ of the loop's "
              "final estimate)") if online else ""
    line = (f"identification: k̂ {k_hat[last] / 1e3:.2f} N/mm, ĉ {c_hat[last] / 1e3:.3f} N·s/mm at the last contact{spread} "
            f"(scenario {k / 1e3:.2f} N/mm, {c / 1e3:.3f} N·s/mm); mean error over {ident.get('samples')} contact "
            f"samples after the first collision: k {k_err * 100:.3g} %, c {c_err / 1e3:.3g} N·s/mm")
    lines = [(line, False)]
    if online and (abs(online["stiffness"] - k) > 3 * online["stiffness_std"]
                   or abs(online["damping"] - c) > 3 * online["damping_std"]):
        lines.append((f"the loop's final k̂ {online['stiffness'] / 1e3:.2f} N/mm, ĉ {online['damping'] / 1e3:.3f} "
                      "N·s/mm: the scenario's values are outside their 3σ (the facility's contact differs "
                      "from the scenario's, or the identification drifted)", True))
    if k_err is not None and c_err is not None and (k_err > IDENTIFICATION_DRIFT[0] or c_err > IDENTIFICATION_DRIFT[1]):
        rt = run.metrics.get("realtime") or {}
        late, ticks = (rt.get("sensor") or {}).get("late", 0), rt.get("ticks") or 1
        cause = (f"; {late / ticks:.0%} of the ticks had no new sensor record (late), so their force was older than "
                 "the kinematics it was identified against (docs/identification.md, real time)") if late > 0.05 * ticks else ""
        lines.append((f"the identification drifts (k {k_err * 100:.3g} % > {IDENTIFICATION_DRIFT[0] * 100:g} % "
                      f"or c {c_err:.3g} > {IDENTIFICATION_DRIFT[1]:g} N·s/m){cause}", True))
    return lines


def _online_identification(run: Run) -> dict[str, Any] | None:
    """The loop's final k̂, ĉ with their standard deviations (:func:`recording.online_identification`
    over the run's own time series), None when its columns or an update are missing."""
    from ..recording import IDENTIFY_COLUMNS, Recording, RecordingError, online_identification

    if any(name not in run.timeseries.columns for name in IDENTIFY_COLUMNS):
        return None
    try:
        return online_identification(Recording(source="run", data=run.timeseries, scenario=run.scenario))
    except RecordingError:
        return None


def _vector(values: Sequence[float] | None, scale: float = 1.0, fmt: str = ".2f") -> str:
    if values is None:
        return "-"
    return "(" + ", ".join(f"{v * scale:{fmt}}" for v in values) + ")"


def _rate(hz: float | None) -> str:
    return "-" if hz is None else f"{hz:.0f} Hz"


def _stats_line(stats: dict[str, Any]) -> str:
    """A link's counters: received, accepted, then every other non-zero counter (`sent` always:
    the robot's must stay 0)."""
    rest = [f"{k} {v}" for k, v in stats.items() if k not in ("received", "accepted", "sent") and v]
    return ", ".join([f"received {stats.get('received')}", f"accepted {stats.get('accepted')}",
                      f"sent {stats.get('sent')}", *rest])


def _link_report(report: dict[str, Any]) -> str:
    """What a link reports of its device (RDT: counts per unit, the sensor's units), as text."""
    parts = []
    for key, value in report.items():
        if isinstance(value, dict):
            value = ", ".join(f"{k} {v}" for k, v in value.items())
        elif isinstance(value, float):
            value = f"{value:g}"
        parts.append(f"{key}: {value}")
    return "; ".join(parts) or "-"


def _report_check(console: Console, report: dict[str, Any]) -> None:
    """`hilcontact check`'s report: both links, aligned, then the verdict."""
    sensor, robot = report["sensor"], report["robot"]
    table = Table.grid(padding=(0, 2))
    table.add_column(style="bold")
    table.add_column()
    table.add_row(f"sensor ({escape(sensor['protocol'])})", escape(sensor["address"]))
    table.add_row("  records", f"{_rate(sensor['rate'])}; {_stats_line(sensor['stats'])}")
    table.add_row("  device", escape(_link_report(sensor["report"])))
    offset, noise = sensor["offset"], sensor["noise"]
    if offset is None:
        table.add_row("  offset", "- (no record)")
    else:
        table.add_row(
            "  offset",
            f"F {_vector(offset[:3])} N, |F| {sensor['offset_force']:.2f} N (max {sensor['offset_max_force']:g} N); "
            f"M {_vector(offset[3:], fmt='.3f')} N m, |M| {sensor['offset_moment']:.3f} N m (max {sensor['offset_max_moment']:g} N m); "
            f"offset mode {sensor['offset_mode']}; {sensor['samples']} records",
        )
        table.add_row("  noise (std)", f"F {_vector(noise[:3], fmt='.3f')} N; M {_vector(noise[3:], fmt='.4f')} N m")
    table.add_row(f"robot ({escape(robot['protocol'])})", escape(robot["address"]))
    table.add_row("  locked onto", escape(robot["peer"] or "-"))
    table.add_row("  feedback", f"{_rate(robot['rate'])}; {_stats_line(robot['stats'])}")
    start = f"the scenario's start {_vector(robot['start_rod_tip'], 1e3, '.1f')} mm"
    if robot["start_distance"] is None:
        table.add_row("  rod tip", f"- (no feedback); {start}")
    else:
        table.add_row(
            "  rod tip",
            f"{_vector(robot['rod_tip'], 1e3, '.1f')} mm, {robot['start_distance'] * 1e3:.1f} mm from {start} "
            f"(start_tolerance {robot['start_tolerance'] * 1e3:.1f} mm)",
        )
    console.print(f"check {escape(report['scenario'])}: listened {report['duration']:g} s, nothing commanded to the robot")
    console.print(table)
    if report["would_start"]:
        console.print("[bold green]verdict: a run would start[/]")
    else:
        console.print("[bold red]verdict: a run would refuse:[/]")
        for reason in report["reasons"]:
            console.print("  - " + escape(reason), soft_wrap=True)
