"""The ``hilcontact`` command line.

    hilcontact run SCENARIO [--set KEY=VALUE ...] [--out DIR] [--no-plots]
    hilcontact compare SCENARIO [--set KEY=VALUE ...] [--compensators LIST] [--out DIR] [--no-plots]
    hilcontact sweep SCENARIO --grid KEY=START:STOP:COUNT|KEY=A,B,... [--compensators LIST]
                     [--seeds N] [--set KEY=VALUE ...] --out DIR [--resume] [--dask ADDRESS]
    hilcontact stability-map SWEEP_DIR [--out DIR] [--cov-tolerance 0.05] [--cof-limit 1.2]
    hilcontact presets
    hilcontact show SCENARIO [--set KEY=VALUE ...]
    hilcontact --version

Bad input (scenario, override, output folder) prints one ``error: ...`` line on stderr and
exits with code 2; nothing is written then. An interrupted sweep (Ctrl-C) keeps its finished
rows and exits with code 130.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import click
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from . import __version__
from .comparison import ALL_KINDS, Comparison, comparison_scenarios, run_comparison
from .errors import HilContactError, ScenarioError
from .run import Run, core_version, simulate
from .scenario import load_scenario, presets

__all__ = ["cli", "main", "parse_set_options"]


def parse_set_options(items: Sequence[str]) -> dict[str, Any]:
    """``KEY=VALUE`` strings to an overrides dict. VALUE is read as a TOML value
    (``0.02``, ``true``, ``[0, 0, 1]``, ``"text"``) and, if that fails, kept as a string."""
    overrides: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ScenarioError(f"--set {item!r}: expected KEY=VALUE, e.g. --set facility.robot_delay=0.02")
        try:
            value: Any = tomllib.loads("v = " + raw.strip())["v"]
        except tomllib.TOMLDecodeError:
            value = raw.strip()
        overrides[key] = value
    return overrides


def _fail(message: str, code: int) -> None:
    click.echo("error: " + " ".join(message.split("\n")), err=True)
    raise click.exceptions.Exit(code)


@contextmanager
def _errors() -> Iterator[None]:
    try:
        yield
    except ScenarioError as exc:
        _fail(str(exc), 2)
    except HilContactError as exc:
        _fail(str(exc), 1)


def _print_version(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    if not value or ctx.resilient_parsing:
        return
    click.echo(f"hilcontact {__version__} (core {core_version() or 'not built'})")
    ctx.exit()


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option(
    "--version",
    is_flag=True,
    expose_value=False,
    is_eager=True,
    callback=_print_version,
    help="Show the version and exit.",
)
def cli() -> None:
    """Hardware-in-the-loop simulation of satellite contact.

    \b
    Examples:
      hilcontact presets
      hilcontact run paper-table1
      hilcontact run paper-table1 --set facility.robot_delay=0.02 --out runs/delay-20ms
      hilcontact compare paper-table1 --set facility.robot_delay=0.02
      hilcontact show paper-table1 > my-scenario.toml
      hilcontact sweep paper-table1 --grid facility.robot_delay=0.002:0.06:30 \\
          --grid servicer.mass=100,300,600,1200 --compensators none,pida --seeds 2 --out sweeps/s1
      hilcontact stability-map sweeps/s1
    """


_SET_HELP = (
    "Override a scenario value, e.g. --set facility.robot_delay=0.02 (VALUE is a TOML value, "
    "or a plain string). Repeatable."
)


@cli.command(short_help="Simulate a scenario and save the results.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@click.option("--out", "out", metavar="DIR", default=None, help="Output folder [default: runs/<scenario name>].")
@click.option("--no-plots", is_flag=True, help="Do not write the PNG figures.")
def run(scenario: str, sets: tuple[str, ...], out: str | None, no_plots: bool) -> None:
    """Simulate SCENARIO (a preset name or a TOML file) and save the results."""
    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
        folder = Path(out) if out is not None else Path("runs") / resolved.name
        if folder.exists() and not folder.is_dir():
            raise ScenarioError(f"--out {folder}: exists and is not a directory")
        with Console(stderr=True).status(f"Simulating {escape(resolved.name)} ..."):
            result = simulate(resolved)
        result.save(folder, plots=not no_plots)
    _report(Console(), result, folder)


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
    )
    for header in ("#", "start (s)", "end (s)", "CoV", "CoF", "peak force (N)",
                   "rebound speed (mm/s)", "reference rebound (mm/s)"):
        table.add_column(header, justify="right")
    for number, row in result.collision_table().iterrows():
        table.add_row(
            str(number),
            _number(row["start"], ".3f"),
            _number(row["end"], ".3f"),
            _number(row["cov"], ".3f"),
            _number(row["cof"], ".3f"),
            _number(row["peak_force"], ".1f"),
            _number(row["rebound_speed"], ".2f", 1e3),
            _number(row["reference_rebound_speed"], ".2f", 1e3),
        )
    if table.row_count:
        console.print(table)
    else:
        console.print("no collisions")
    if result.status == "ok":
        console.print("status: [green]ok[/green]")
    else:
        at = result.metrics.get("diverged_at")
        when = f" at {at:.3f} s" if isinstance(at, (int, float)) else ""
        reason = result.metrics.get("reason") or "no reason given"
        console.print(
            f"[bold red]status: {escape(result.status)}{when}: {escape(str(reason))}[/bold red]", soft_wrap=True
        )
    files = ", ".join(sorted(p.name for p in folder.iterdir()))
    console.print(f"saved to {escape(str(folder))}/ ({escape(files)})", soft_wrap=True)


@cli.command(name="compare", short_help="Run several compensators on one scenario and compare them.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@click.option(
    "--compensators",
    "kinds",
    metavar="LIST",
    default=",".join(ALL_KINDS),
    show_default=True,
    help="Comma-separated compensator kinds to run.",
)
@click.option(
    "--out", "out", metavar="DIR", default=None, help="Output folder [default: runs/<scenario name>-compare]."
)
@click.option("--no-plots", is_flag=True, help="Do not write the PNG figures.")
def compare_command(scenario: str, sets: tuple[str, ...], kinds: str, out: str | None, no_plots: bool) -> None:
    """Simulate SCENARIO once per compensator and compare them.

    Writes a run folder per compensator, comparison.md and comparison.csv (CoV, CoF, peak
    force, rebound speed per collision; status and identification errors per compensator)
    and the compare_*.png figures.
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    with _errors():
        overrides = parse_set_options(sets)
        scenarios = comparison_scenarios(scenario, kinds, overrides)  # validate all before running
        name = next(iter(scenarios.values())).name
        folder = Path(out) if out is not None else Path("runs") / f"{name}-compare"
        if folder.exists() and not folder.is_dir():
            raise ScenarioError(f"--out {folder}: exists and is not a directory")
        stderr = Console(stderr=True)
        with Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=stderr,
            transient=True,
        ) as progress:
            task = progress.add_task(f"Simulating {escape(name)}", total=len(scenarios))

            def advance(kind: str, index: int, total: int) -> None:
                progress.update(task, completed=index, description=f"Simulating {escape(name)}: {escape(kind)}")

            result = run_comparison(scenarios, progress=advance)
            progress.update(task, completed=len(scenarios), description="Writing files")
            result.save(folder, plots=not no_plots)
    _report_comparison(Console(), result, folder)


def _report_comparison(console: Console, result: Comparison, folder: Path) -> None:
    s = result.scenario
    table = Table(
        title=f"{s.name}: robot delay {s.facility.robot_delay * 1e3:g} ms, "
        f"sensor delay {s.facility.sensor_delay * 1e3:g} ms",
    )
    table.add_column("compensator", no_wrap=True)
    table.add_column("status")
    table.add_column("CoV per collision")
    for header in ("worst CoF", "k error (%)", "c error (N·s/mm)"):
        table.add_column(header, justify="right")
    for kind, row in result.summary.iterrows():
        if row["status"] == "ok":
            status = "[green]ok[/green]"
        else:
            at = row["diverged_at"]
            when = f" {at:.2f} s" if math.isfinite(at) else ""
            status = f"[bold red]{escape(str(row['status']))}{when}[/bold red]"
        table.add_row(
            escape(str(kind)),
            status,
            " ".join(_number(v, ".2f") for v in row["cov"]) or "-",
            _number(row["worst_cof"], ".3f"),
            _number(row["stiffness_error_pct"], ".3g"),
            _number(row["damping_error_Ns_mm"], ".3g"),
        )
    console.print(table)
    console.print(
        "CoV, CoF: rebound speed and peak force / ideal reference (1 is perfect); "
        "mean CoV and worst |CoV-1| in comparison.md",
        soft_wrap=True,
    )
    files = ", ".join(sorted(p.name + ("/" if p.is_dir() else "") for p in folder.iterdir()))
    console.print(f"saved to {escape(str(folder))}/ ({escape(files)})", soft_wrap=True)


@cli.command(name="sweep", short_help="Run a scenario over a grid of values, compensators and seeds.")
@click.argument("scenario")
@click.option(
    "--grid",
    "grids",
    multiple=True,
    metavar="KEY=SPEC",
    help="A swept key: KEY=START:STOP:COUNT (both ends included) or KEY=A,B,C. Repeatable; "
    "the grid is every combination.",
)
@click.option(
    "--compensators",
    "kinds",
    metavar="LIST",
    default=",".join(ALL_KINDS),
    show_default=True,
    help="Comma-separated compensator kinds to run at every grid point.",
)
@click.option("--seeds", default=1, show_default=True, type=int, help="Noise seeds per grid point.")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@click.option("--out", "out", metavar="DIR", required=True, help="Sweep folder (results.parquet, sweep.json).")
@click.option("--resume", is_flag=True, help="Continue the sweep in --out, skipping its finished runs.")
@click.option(
    "--dask",
    metavar="ADDRESS",
    default=None,
    help="Run on a Dask cluster: a scheduler address (tcp://host:8786) or 'local' (a LocalCluster).",
)
@click.option("--threads", type=int, default=None, help="Rust threads for a local sweep [default: one per core].")
def sweep_command(
    scenario: str,
    grids: tuple[str, ...],
    kinds: str,
    seeds: int,
    sets: tuple[str, ...],
    out: str,
    resume: bool,
    dask: str | None,
    threads: int | None,
) -> None:
    """Run SCENARIO at every point of the grid, with every compensator and seed.

    Writes one row per run (swept values, compensator, seed, status, worst and mean CoV and
    CoF, identification error, wall time) to DIR/results.parquet. Ctrl-C keeps the finished
    rows; rerun with --resume to skip them.
    """
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from .sweep import plan_sweep, run_plan

    if threads is not None and threads < 1:
        _fail("--threads: expected a whole number >= 1", 2)
    with _errors():
        overrides = parse_set_options(sets)
        plan = plan_sweep(scenario, list(grids), kinds, seeds, overrides)  # validate before anything runs
        stderr = Console(stderr=True)
        where = f"on Dask ({dask})" if dask else f"on {threads or 'all'} core(s)"
        stderr.print(
            f"{plan.size} runs: {len(plan.points)} grid point(s) x {len(plan.compensators)} compensator(s) "
            f"x {len(plan.seeds)} seed(s), {where}",
            soft_wrap=True,
        )
        columns = (
            TextColumn("[bold]sweep"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("elapsed"),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
        )
        try:
            with Progress(*columns, console=stderr, transient=True) as bar:
                task = bar.add_task("sweep", total=plan.size)
                rows = run_plan(
                    plan,
                    out,
                    resume=resume,
                    dask=dask,
                    threads=threads,
                    progress=lambda done, total: bar.update(task, completed=done, total=total),
                )
        except KeyboardInterrupt:
            from .sweep import load_results

            try:
                saved = len(load_results(out))
            except HilContactError:
                saved = 0
            click.echo(
                f"interrupted: {saved} finished run(s) saved in {out}/results.parquet; "
                "rerun with --resume to continue",
                err=True,
            )
            raise click.exceptions.Exit(130) from None
    _report_sweep(Console(), rows, out)


def _report_sweep(console: Console, rows: Any, out: str) -> None:
    from .stability import faithful

    table = Table(title=f"sweep: {len(rows)} runs")
    for header in ("compensator", "runs", "ok", "diverged", "faithful", "median wall time (ms)"):
        table.add_column(header, justify="right" if header != "compensator" else "left")
    marks = faithful(rows)
    for kind, group in rows.groupby("compensator", sort=False):
        ok = int((group["status"] == "ok").sum())
        table.add_row(
            escape(str(kind)),
            str(len(group)),
            str(ok),
            str(len(group) - ok),
            f"{int(marks[group.index].sum())}",
            _number(group["wall_time"].median(), ".2f", 1e3),
        )
    console.print(table)
    console.print("faithful: ok, |CoV-1| <= 5 %, CoF <= 1.2 (see hilcontact stability-map)", soft_wrap=True)
    console.print(f"saved to {escape(out)}/results.parquet", soft_wrap=True)


@cli.command(name="stability-map", short_help="Map where each compensator stays faithful in a sweep.")
@click.argument("sweep_dir", metavar="SWEEP_DIR")
@click.option("--out", "out", metavar="DIR", default=None, help="Output folder [default: SWEEP_DIR].")
@click.option("--cov-tolerance", default=0.05, show_default=True, type=float, help="Faithful: |CoV - 1| <= this.")
@click.option("--cof-limit", default=1.2, show_default=True, type=float, help="Faithful: CoF <= this.")
def stability_map_command(sweep_dir: str, out: str | None, cov_tolerance: float, cof_limit: float) -> None:
    """Draw, per compensator, the (contact frequency, robot delay) region where every run is
    faithful, heat maps of the worst CoV and CoF, and print the maximal faithful delay per
    compensator and contact frequency.

    Writes stability_map.png, worst_cov.png, worst_cof.png, max_faithful_delay.csv and
    cells.csv into DIR.
    """
    from .stability import MAP_FILES, stability_map

    with _errors():
        if not Path(sweep_dir).is_dir():
            raise ScenarioError(f"{sweep_dir}: not a sweep folder")
        result = stability_map(sweep_dir, cov_tolerance=cov_tolerance, cof_limit=cof_limit)
        folder = result.save(out if out is not None else sweep_dir)
    best = result.max_faithful_delay()
    table = Table(title=f"maximal faithful robot delay (ms): |CoV-1| <= {cov_tolerance:g}, CoF <= {cof_limit:g}")
    table.add_column("contact frequency (Hz)", justify="right")
    for kind in best.columns:
        table.add_column(escape(str(kind)), justify="right")
    for freq, row in best.iterrows():
        table.add_row(_number(freq, ".2f"), *(_number(v, "g", 1e3) for v in row))
    console = Console()
    console.print(table)
    console.print("- : not faithful even at the smallest swept delay", soft_wrap=True)
    console.print(f"saved to {escape(str(folder))}/ ({', '.join(MAP_FILES)})", soft_wrap=True)


@cli.command(name="presets")
def presets_command() -> None:
    """List the embedded presets."""
    with _errors():
        listing = presets()
    width = max((len(name) for name in listing), default=0)
    for name, description in listing.items():
        click.echo(f"{name:<{width}}  {description}")


@cli.command(short_help="Print a scenario's resolved TOML.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
def show(scenario: str, sets: tuple[str, ...]) -> None:
    """Print the resolved TOML of SCENARIO (a preset name or a TOML file)."""
    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
    click.echo(resolved.to_toml(), nl=False)


def main(argv: Sequence[str] | None = None) -> None:
    """Console-script entry point."""
    cli.main(args=list(argv) if argv is not None else None, prog_name="hilcontact")
