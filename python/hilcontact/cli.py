"""The ``hilcontact`` command line.

    hilcontact run SCENARIO [--set KEY=VALUE ...] [--out DIR] [--no-plots] [--mcap FILE]
    hilcontact compare SCENARIO [--set KEY=VALUE ...] [--compensators LIST] [--out DIR] [--no-plots] [--run-figures]
    hilcontact plot RUN_OR_COMPARISON_DIR
    hilcontact identify LOG --out DIR [--scenario FILE] [--wrench-topic T --pose-topic T ...]
    hilcontact replay LOG --compensator KIND [--set compensator.KEY=VALUE ...] --out DIR
    hilcontact sweep SCENARIO --grid KEY=START:STOP:COUNT|KEY=A,B,... [--compensators LIST]
                     [--seeds N] [--set KEY=VALUE ...] --out DIR [--resume] [--dask ADDRESS]
    hilcontact stability-map SWEEP_DIR [--out DIR] [--cov-tolerance 0.05] [--cof-limit 1.2]
    hilcontact presets
    hilcontact init FILE.toml [--from PRESET] [--set KEY=VALUE ...]
    hilcontact show SCENARIO [--set KEY=VALUE ...]
    hilcontact facility SCENARIO [--sensor-port 49152 --http-port 80 --egm-host H --egm-port 6510 ...]
    hilcontact hil SCENARIO --sensor HOST [--sensor-protocol rdt|sri --robot-protocol egm|rsi --robot-port N
                   --robot-option KEY=VALUE --force-limit N --rt-priority 80 --cpu N ...] [--out DIR] [--mcap FILE]
    hilcontact check SCENARIO --sensor HOST [the options of hil] [--duration 1] [--out DIR]
    hilcontact demo-rt [SCENARIO] [--compensator pida] [--rt-priority 80 --no-lock-memory --cpu N] [--out DIR] [--mcap FILE]
    hilcontact --version

Bad input (scenario, override, option, output folder) prints one ``error: ...`` line on stderr
and exits with code 2; nothing is written then. ``hil`` and ``demo-rt`` exit with 3 after a
safety stop and 130 after Ctrl-C (the run is saved in both cases); a facility that cannot be
reached or a port in use exits with 1. ``check`` exits with 0 when a run would start, 1 when it
would refuse. An interrupted sweep (Ctrl-C) keeps its finished rows
and exits with code 130.
"""

from __future__ import annotations

import json
import math
import signal
import socket
import sys
import threading
import time
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
from .errors import HilContactError, RealtimeOptionError, ScenarioError
from .limits import Limits, check_run
from .output import OutputError, check_output_folder
from .run import Run, core_version, simulate
from .scenario import load_scenario, presets

__all__ = ["cli", "main", "parse_set_options"]


def parse_set_options(items: Sequence[str], option: str = "--set",
                      example: str = "facility.robot_delay=0.02") -> dict[str, Any]:
    """``KEY=VALUE`` strings to an overrides dict. VALUE is read as a TOML value
    (``0.02``, ``true``, ``[0, 0, 1]``, ``"text"``) and, if that fails, kept as a string.
    ``option`` and ``example`` name the command-line option in the error."""
    overrides: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ScenarioError(f"{option} {item!r}: expected KEY=VALUE, e.g. {option} {example}")
        try:
            value: Any = tomllib.loads("v = " + raw.strip())["v"]
        except tomllib.TOMLDecodeError:
            value = raw.strip()
        except RecursionError:
            raise ScenarioError(f"--set {key}: the value is nested too deeply") from None
        overrides[key] = value
    return overrides


def _one_line(message: str) -> str:
    return "error: " + " ".join(message.split("\n"))


def _fail(message: str, code: int) -> None:
    click.echo(_one_line(message), err=True)
    raise click.exceptions.Exit(code)


class _Cli(click.Group):
    """The command group; a usage error (an unknown option, a bad option value, a missing
    argument) is one ``error: ...`` line on stderr and exit code 2, like every bad input."""

    def main(self, *args: Any, standalone_mode: bool = True, **kwargs: Any) -> Any:
        if not standalone_mode:
            return super().main(*args, standalone_mode=False, **kwargs)
        try:
            code = super().main(*args, standalone_mode=False, **kwargs)
        except click.UsageError as exc:
            command = exc.ctx.command_path + ": " if exc.ctx is not None and exc.ctx.parent is not None else ""
            click.echo(_one_line(command + exc.format_message()), err=True)
            sys.exit(exc.exit_code)
        except click.ClickException as exc:
            click.echo(_one_line(exc.format_message()), err=True)
            sys.exit(exc.exit_code)
        except (click.Abort, KeyboardInterrupt, EOFError):
            click.echo("Aborted!", err=True)
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


class _Number(click.ParamType):
    """A finite number in a range (NaN, ±inf and values out of range refused, naming the
    option): ``_Number(min=0, min_open=True)`` is > 0."""

    name = "number"

    def __init__(self, min: float | None = None, max: float | None = None, min_open: bool = False) -> None:
        self.min, self.max, self.min_open = min, max, min_open

    def _allowed(self) -> str:
        parts = []
        if self.min is not None:
            parts.append(f"{'>' if self.min_open else '>='} {self.min:g}")
        if self.max is not None:
            parts.append(f"<= {self.max:g}")
        return "a finite number" + (" " + " and ".join(parts) if parts else "")

    def convert(self, value: Any, param: Any, ctx: Any) -> float:
        try:
            number = float(value)
        except (TypeError, ValueError):
            self.fail(f"expected {self._allowed()}, got {value!r}", param, ctx)
        below = self.min is not None and (number <= self.min if self.min_open else number < self.min)
        above = self.max is not None and number > self.max
        if not math.isfinite(number) or below or above:
            self.fail(f"expected {self._allowed()}, got {value!r}", param, ctx)
        return number


#: Option types: any finite number, a positive one, one >= 0.
NUMBER = _Number()
POSITIVE = _Number(min=0.0, min_open=True)
NON_NEGATIVE = _Number(min=0.0)
PORT = click.IntRange(0, 65535)


def _stop_on_sigterm() -> None:
    """SIGTERM (``kill``) stops a batch command as Ctrl-C does: whatever it was writing is
    removed (hilcontact.output) and nothing is left half-written. Only in the main thread (the
    only one Python lets set a handler)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)


def _with(options: list[Any]) -> Any:
    def decorate(f: Any) -> Any:
        for option in reversed(options):
            f = option(f)
        return f

    return decorate


_LIMIT_OPTIONS = [
    click.option("--max-memory", type=POSITIVE, default=Limits.max_memory, show_default=True, metavar="GB",
                 help="Refuse to start when the estimated memory is above this, GB."),
    click.option("--max-time", type=POSITIVE, default=Limits.max_time, show_default=True, metavar="S",
                 help="Refuse to start when the estimated time (on one core) is above this, s."),
]


@contextmanager
def _errors() -> Iterator[None]:
    try:
        yield
    except (ScenarioError, RealtimeOptionError, OutputError) as exc:
        _fail(str(exc), 2)
    except HilContactError as exc:
        _fail(str(exc), 1)
    except OSError as exc:  # a disk or permission error that no command turned into an OutputError
        where = f"{exc.filename}: " if exc.filename else ""
        _fail(f"{where}{exc.strerror or exc}", 2)


_FORCE_HELP = "Replace --out even if it holds files hilcontact did not write."


def _out_folder(out: str | None, default: Path, force: bool) -> Path:
    """The output folder, checked before anything runs (hilcontact.output)."""
    folder = Path(out) if out is not None else default
    check_output_folder(folder, overwrite=force)
    return folder


_MCAP_HELP = (
    "Also record the run as an MCAP file (ROS 2 messages that Foxglove, Lichtblick and "
    "PlotJuggler open): measured and applied wrench, commanded and actual rod tip, velocities, "
    "energy, estimates, events; written in chunks, so a killed run keeps all but its last "
    "0.5 s. An existing FILE is refused unless --force."
)


def _mcap_file(mcap: str | None, folder: Path, force: bool) -> Path | None:
    """The --mcap file, checked before anything runs: never a user's file replaced silently
    (``--force`` allows it), never a directory, never inside --out (replaced as a whole)."""
    if mcap is None:
        return None
    path = Path(mcap)
    if path.is_dir():
        raise OutputError(f"--mcap {mcap}: is a directory; give a file name, e.g. --mcap run.mcap")
    if path.exists() and not force:
        raise OutputError(f"--mcap {mcap}: exists; choose another file, or add --force to replace it")
    target, out = path.absolute(), folder.absolute()
    if target == out or out in target.parents:
        raise OutputError(
            f"--mcap {mcap}: is inside --out {folder}, which is replaced as a whole when the run is saved; "
            "write it elsewhere"
        )
    return path


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


def _print_version(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    if not value or ctx.resilient_parsing:
        return
    click.echo(f"hilcontact {__version__} (core {core_version() or 'not built'})")
    ctx.exit()


@click.group(cls=_Cli, context_settings={"help_option_names": ["-h", "--help"]})
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
@click.option("--mcap", "mcap", metavar="FILE", default=None, help=_MCAP_HELP)
@click.option("--force", is_flag=True, help=_FORCE_HELP + " Replace --mcap FILE.")
@_with(_LIMIT_OPTIONS)
def run(scenario: str, sets: tuple[str, ...], out: str | None, no_plots: bool, mcap: str | None, force: bool,
        max_memory: float, max_time: float) -> None:
    """Simulate SCENARIO (a preset name or a TOML file) and save the results."""
    _stop_on_sigterm()
    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
        check_run(resolved, Limits(max_memory, max_time))
        folder = _out_folder(out, Path("runs") / resolved.name, force)
        mcap_path = _mcap_file(mcap, folder, force)
        with Console(stderr=True).status(f"Simulating {escape(resolved.name)} ..."):
            result = simulate(resolved, mcap=mcap_path, overwrite=force)
        result.save(folder, plots=not no_plots, overwrite=force)
    console = Console()
    _report(console, result, folder)
    _report_mcap(console, result.mcap)


@cli.command(short_help="Redraw the figures of a run or comparison folder.")
@click.argument("folder", type=click.Path(file_okay=False, path_type=Path))
@click.option("--force", is_flag=True, help="Draw into a folder that hilcontact did not write (it has the run files but no .hilcontact.json).")
def plot(folder: Path, force: bool) -> None:
    """Redraw the PNG figures of FOLDER, a run folder (`run`, `hil`, a compensator of a
    comparison) or a comparison folder (its compare_*.png and every compensator's figures),
    from the data files in it: after `--no-plots`, after a compare without --run-figures, or
    after an update of hilcontact. Only PNG files are written.

    \b
    Examples:
      hilcontact plot runs/paper-table1
      hilcontact plot runs/paper-table1-compare
    """
    from rich.progress import Progress

    from .output import marker_kind

    with _errors():
        if not folder.is_dir():
            raise ScenarioError(f"{folder}: no such folder")
        kind = marker_kind(folder)
        if kind is None and not force:
            raise OutputError(f"{folder}: not written by hilcontact (no .hilcontact.json); --force draws into it anyway")
        if kind not in (None, "run", "comparison"):
            raise ScenarioError(f"{folder}: a {kind} folder; plot draws run and comparison folders")
        if (folder / "metrics.json").is_file():
            targets: list[tuple[Path, Any]] = [(folder, Run.load(folder))]
        else:
            comparison = Comparison.load(folder)
            targets = [(folder, comparison)] + [(folder / k, r) for k, r in comparison.runs.items()]
        written: list[Path] = []
        with Progress(console=Console(stderr=True), transient=True) as progress:
            task = progress.add_task("Drawing", total=len(targets))
            for where, result in targets:
                progress.update(task, description=f"Drawing {escape(str(where))}")
                try:
                    written += [where / f"{name}.png" for name in result.plot(where)]
                except OSError as exc:
                    raise OutputError(f"{where}: cannot write the figures: {exc.strerror or exc}") from None
                progress.advance(task)
    click.echo(f"drew {len(written)} figures in {folder}/")


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
    for header in ("#", "start (s)", "end (s)", "CoV", "CoF", "v error (%)", "peak force (N)",
                   "rebound speed (mm/s)", "reference rebound (mm/s)"):
        table.add_column(header, justify="right")
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
        if not result.collision_table()["complete"].all():
            console.print("*: still under way at the end of the run (no rebound, not compared)")
    else:
        console.print("no collisions")
    if result.status == "ok":
        console.print("status: [green]ok[/green]")
    elif result.status == "unfaithful":
        violations = result.metrics.get("violations") or []
        console.print("[bold yellow]status: unfaithful[/bold yellow] (tolerances in the scenario's [metrics])")
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
@click.option("--run-figures", is_flag=True, help="Also draw each compensator's own figures (slower; `hilcontact plot DIR` draws them later).")
@click.option("--force", is_flag=True, help=_FORCE_HELP)
@_with(_LIMIT_OPTIONS)
def compare_command(scenario: str, sets: tuple[str, ...], kinds: str, out: str | None, no_plots: bool,
                    run_figures: bool, force: bool, max_memory: float, max_time: float) -> None:
    """Simulate SCENARIO once per compensator and compare them.

    Writes a run folder per compensator (data; its figures with --run-figures, or later with
    `hilcontact plot DIR/<compensator>`), comparison.md and comparison.csv (CoV, CoF, peak
    force, rebound speed per collision; status and identification errors per compensator)
    and the compare_*.png figures.
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    _stop_on_sigterm()
    with _errors():
        overrides = parse_set_options(sets)
        scenarios = comparison_scenarios(scenario, kinds, overrides)  # validate all before running
        check_run(next(iter(scenarios.values())), Limits(max_memory, max_time), runs=len(scenarios))
        name = next(iter(scenarios.values())).name
        folder = _out_folder(out, Path("runs") / f"{name}-compare", force)
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
            result.save(folder, plots=not no_plots, overwrite=force, run_plots=run_figures)
    _report_comparison(Console(), result, folder)


def _report_comparison(console: Console, result: Comparison, folder: Path) -> None:
    s = result.scenario
    table = Table(
        title=f"{s.name}: robot delay {s.facility.robot_delay * 1e3:g} ms, "
        f"sensor delay {s.facility.sensor_delay * 1e3:g} ms",
    )
    table.add_column("compensator", no_wrap=True)
    table.add_column("status", no_wrap=True)
    table.add_column("CoV per collision")
    for header in ("worst CoF", "v error (%)", "k error (%)", "c error (N·s/mm)"):
        table.add_column(header, justify="right")
    for kind, row in result.summary.iterrows():
        if row["status"] == "ok":
            status = "[green]ok[/green]"
        elif row["status"] == "unfaithful":
            status = "[yellow]unfaithful[/yellow]"
        else:
            at = row["diverged_at"]
            when = f" {at:.2f} s" if math.isfinite(at) else ""
            status = f"[bold red]{escape(str(row['status']))}{when}[/bold red]"
        table.add_row(
            escape(str(kind)),
            status,
            " ".join(_number(v, ".2f") for v in row["cov"]) or "-",
            _number(row["worst_cof"], ".3f"),
            _number(row["worst_velocity_error_pct"], ".2f"),
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
@click.option("--threads", type=click.IntRange(1, 1024), default=None, help="Rust threads for a local sweep [default: one per core].")
@_with(_LIMIT_OPTIONS)
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
    max_memory: float,
    max_time: float,
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

    from .sweep import check_sweep_folder, plan_sweep, run_plan

    _stop_on_sigterm()
    with _errors():
        overrides = parse_set_options(sets)
        # validate before anything runs
        plan = plan_sweep(scenario, list(grids), kinds, seeds, overrides, limits=Limits(max_memory, max_time),
                          threads=threads)
        for note in check_sweep_folder(Path(out), plan, resume):
            click.echo("note: " + note, err=True)
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


@cli.command(name="stability-map", short_help="Map where each compensator stays faithful in a sweep.")
@click.argument("sweep_dir", metavar="SWEEP_DIR")
@click.option("--out", "out", metavar="DIR", default=None, help="Output folder [default: SWEEP_DIR].")
@click.option("--cov-tolerance", default=None, type=NON_NEGATIVE,
              help="Stricter than the runs' verdicts: |CoV - 1| <= this on every collision.")
@click.option("--cof-limit", default=None, type=POSITIVE, help="Stricter than the runs' verdicts: CoF <= this on every collision.")
def stability_map_command(sweep_dir: str, out: str | None, cov_tolerance: float | None, cof_limit: float | None) -> None:
    """Draw, per compensator, the (contact frequency, robot delay) region where every run is
    faithful (status ok: the scenario's [metrics] tolerances, from judge_from on), heat maps of the worst CoV and CoF, and print the maximal faithful delay per
    compensator and contact frequency.

    Writes stability_map.png, worst_cov.png, worst_cof.png, max_faithful_delay.csv and
    cells.csv into DIR.
    """
    from .stability import MAP_FILES, criterion_text, stability_map

    with _errors():
        if not Path(sweep_dir).is_dir():
            raise ScenarioError(f"{sweep_dir}: not a sweep folder")
        result = stability_map(sweep_dir, cov_tolerance=cov_tolerance, cof_limit=cof_limit)
        folder = result.save(out if out is not None else sweep_dir)
    best = result.max_faithful_delay()
    table = Table(title=f"maximal faithful robot delay (ms): {criterion_text(cov_tolerance, cof_limit)}")
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


@cli.command(short_help="Write a scenario file to start from, every key commented.")
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--from", "source", default="paper-table1", show_default=True, metavar="SCENARIO",
              help="The preset (or TOML file) whose values the file takes.")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@click.option("--force", is_flag=True, help="Replace FILE if it exists.")
def init(file: Path, source: str, sets: tuple[str, ...], force: bool) -> None:
    """Write FILE, a scenario with every key, each with a comment giving its meaning, unit and
    default, and the values of --from (a preset, paper-table1 by default). Edit it, then
    `hilcontact run FILE`. An existing FILE is kept unless --force.

    \b
    Examples:
      hilcontact init my.toml
      hilcontact init oblique.toml --from oblique-6dof --set compensator.kind=pida
    """
    from .template import write_template

    with _errors():
        resolved = load_scenario(source, parse_set_options(sets))
        written = write_template(file, resolved, overwrite=force)
    click.echo(f"wrote {written} (from {resolved.name}); run it with: hilcontact run {written}")


@cli.command(short_help="Print a scenario's resolved TOML.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
def show(scenario: str, sets: tuple[str, ...]) -> None:
    """Print the resolved TOML of SCENARIO (a preset name or a TOML file)."""
    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
    click.echo(resolved.to_toml(), nl=False)


# --------------------------------------------------------------------------------------
# Real time: the emulated facility, the HIL loop, the demo
# --------------------------------------------------------------------------------------


def _rt_defaults() -> dict[str, dict[str, Any]]:
    from .realtime import realtime_defaults

    try:
        return realtime_defaults()
    except HilContactError:  # native core not built: help without defaults
        return {"runtime": {}, "facility": {}, "protocols": {}}


_RT_DEFAULTS = _rt_defaults()


def _dflt(section: str, key: str, unit: str = "") -> str:
    """``[default: VALUE UNIT]`` from the Rust defaults (the one place they live)."""
    value: Any = _RT_DEFAULTS.get(section, {})
    for part in key.split("."):
        value = value.get(part) if isinstance(value, dict) else None
    if value is None:
        return ""
    if isinstance(value, list):
        value = ",".join(f"{v:g}" for v in value)
    return f" [default: {value}{' ' + unit if unit else ''}]"


def _protocols(link: str) -> list[str]:
    """The protocols of a link (``sensor``/``robot``), from the Rust registry (the one list)."""
    return list(_RT_DEFAULTS.get("protocols", {}).get(link, []))


def _protocol_option(link: str, section: str) -> Any:
    choices = _protocols(link)
    return click.option(
        f"--{link}-protocol", f"{link}_protocol", default=None,
        type=click.Choice(choices) if choices else str,
        help=f"Protocol of the {link}." + _dflt(section, f"{link}.kind"),
    )


def _numbers(text: str | None, n: int, option: str) -> list[float] | None:
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise RealtimeOptionError(f"{option} {text!r}: expected {n} comma-separated numbers")
    return values


def _raise_keyboard_interrupt(_signum: int, _frame: Any) -> None:
    raise KeyboardInterrupt


def _stop_on_signals() -> None:
    """Ctrl-C (SIGINT) and SIGTERM stop a real-time command cleanly (hold, stop streaming, save),
    even when the process was started with SIGINT ignored (a background job of a
    non-interactive shell inherits SIG_IGN, and Python then keeps it)."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)


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
        f"facility  t {s['time']:8.3f} s | contact {s['contact_force']:7.1f} N | {sensor} sent {s['rdt_sent']} | "
        f"{robot} sent {s['egm_sent']}, corrections {s['corrections']} (dropped {s['corrections_dropped']}) | "
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
    if rsi := rt.get("rsi"):
        ans = rsi.get("answer_latency_us", {})
        console.print(
            f"RSI answers: latency p50/p99/max {ans.get('p50', 0):.0f}/{ans.get('p99', 0):.0f}/{ans.get('max', 0):.0f} µs, "
            f"late (> {rsi.get('deadline_us', 0):.0f} µs) {rsi.get('answers_late')}, unanswered {rsi.get('unanswered')}",
            soft_wrap=True,
        )


#: Sensor protocols that stream over TCP (the others over UDP): SRI M812x boxes.
_TCP_SENSORS = ("sri",)


def _sensor_scheme(kind: str) -> str:
    """``tcp`` or ``udp``: the transport of a sensor protocol, for addresses shown to the user."""
    return "tcp" if kind.lower() in _TCP_SENSORS else "udp"


def _link_option_flags(section: str) -> list[Any]:
    """``--robot-port`` (any robot protocol) and ``--sensor-option``/``--robot-option
    KEY=VALUE`` (any key of the protocol's options, e.g. the RSI element names: docs/realtime.md,
    "Options of each protocol")."""
    return [
        click.option("--robot-port", type=click.IntRange(0, 65535), default=None, metavar="PORT",
                     help="UDP port the robot sends its feedback to (the PC's port), any robot protocol [default: the protocol's: EGM 6510, RSI 59152]."),
        click.option("--sensor-option", "sensor_options", multiple=True, metavar="KEY=VALUE",
                     help=f"An option of the {section}'s sensor protocol (repeatable), e.g. sample_rate=1000 for SRI; keys per protocol in docs/realtime.md."),
        click.option("--robot-option", "robot_options", multiple=True, metavar="KEY=VALUE",
                     help=f"An option of the {section}'s robot protocol (repeatable), e.g. correction=relative or state_element=RIst for RSI; keys per protocol in docs/realtime.md."),
    ]


def _link_groups(sensor_protocol: str | None, robot_protocol: str | None, robot_port: int | None,
                 sensor_options: Sequence[str], robot_options: Sequence[str]) -> dict[str, Any]:
    """The ``sensor``/``robot`` option groups from the protocol, port and KEY=VALUE flags (None
    where nothing was given: the defaults)."""
    sensor = parse_set_options(sensor_options, "--sensor-option", "sample_rate=1000")
    robot = parse_set_options(robot_options, "--robot-option", "correction=relative")
    if sensor_protocol:
        sensor["kind"] = sensor_protocol
    if robot_protocol:
        robot["kind"] = robot_protocol
    if robot_port is not None:
        robot["port"] = robot_port
    return {"sensor": sensor or None, "robot": robot or None}


_FACILITY_OPTIONS = [
    click.option("--bind-host", default=None, help="Address the sensor's RDT and HTTP servers bind to." + _dflt("facility", "bind_host")),
    click.option("--sensor-port", type=PORT, default=None, help="RDT (UDP) port of the sensor." + _dflt("facility", "sensor_port")),
    click.option("--http-port", type=PORT, default=None, help="HTTP port of /netftapi2.xml (0 = none)." + _dflt("facility", "http_port")),
    click.option("--egm-host", default=None, help="Host the robot sends EGM feedback to (the PC)." + _dflt("facility", "egm_host")),
    click.option("--egm-port", type=PORT, default=None, help="UDP port the robot sends EGM feedback to." + _dflt("facility", "egm_port")),
    click.option("--egm-local-port", type=PORT, default=None, help="The robot's own UDP port (0 = any)." + _dflt("facility", "egm_local_port")),
    click.option("--counts-per-force", type=NUMBER, default=None, help="RDT counts per N (cfgcpf)." + _dflt("facility", "counts_per_force")),
    click.option("--counts-per-torque", type=NUMBER, default=None, help="RDT counts per N m (cfgcpt)." + _dflt("facility", "counts_per_torque")),
]


_MAPPING_OPTIONS = [
    click.option("--egm-offset", default=None, metavar="X,Y,Z", help="Origin of the target frame t in the EGM frame, mm." + _dflt("runtime", "robot.offset_mm")),
    click.option("--egm-rotation", default=None, metavar="W,X,Y,Z", help="Rotation from t to the EGM frame, quaternion." + _dflt("runtime", "robot.rotation")),
]


@cli.command(name="facility", short_help="Run the emulated facility (Net F/T sensor + ABB EGM robot) in real time.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@_with([_protocol_option("sensor", "facility"), _protocol_option("robot", "facility")] + _FACILITY_OPTIONS + _MAPPING_OPTIONS
       + _link_option_flags("facility"))
@click.option("--silence-sensor-after", type=NON_NEGATIVE, default=None, metavar="S", help="Fault injection: the sensor stops sending S seconds after the robot's first command (the run's start).")
@click.option("--silence-robot-after", type=NON_NEGATIVE, default=None, metavar="S", help="Fault injection: the robot stops sending S seconds after its first command.")
@click.option("--duration", type=POSITIVE, default=None, metavar="S", help="Stop after S seconds [default: run until Ctrl-C].")
def facility_command(scenario: str, sets: tuple[str, ...], sensor_protocol: str | None, robot_protocol: str | None,
                     bind_host: str | None, sensor_port: int | None,
                     http_port: int | None, egm_host: str | None, egm_port: int | None, egm_local_port: int | None,
                     counts_per_force: float | None, counts_per_torque: float | None, egm_offset: str | None,
                     egm_rotation: str | None, robot_port: int | None, sensor_options: tuple[str, ...],
                     robot_options: tuple[str, ...], silence_sensor_after: float | None,
                     silence_robot_after: float | None, duration: float | None) -> None:
    """Emulate the facility of SCENARIO in real time: an F/T sensor speaking ATI's Net F/T RDT
    protocol (UDP, 1 record per control period, /netftapi2.xml over HTTP) and a robot speaking
    ABB's EGM (UDP + protobuf, feedback every 4 ms to --egm-host:--egm-port, corrections back),
    with the scenario's robot delay, sensor delay and noise, and the contact between them.

    \b
    Example (then run `hilcontact hil` against it, see there):
      hilcontact facility paper-table1 --set facility.robot_delay=0.02 --http-port 8080
    """
    from .realtime import start_facility

    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
        # the flags keep their flat keys; hilcontact.realtime.LEGACY_KEYS moves them into the devices
        options = {
            **_link_groups(sensor_protocol, robot_protocol, robot_port, sensor_options, robot_options),
            "bind_host": bind_host, "sensor_port": sensor_port, "http_port": http_port, "egm_host": egm_host,
            "egm_port": egm_port, "egm_local_port": egm_local_port, "counts_per_force": counts_per_force,
            "counts_per_torque": counts_per_torque, "egm_offset_mm": _numbers(egm_offset, 3, "--egm-offset"),
            "egm_rotation": _numbers(egm_rotation, 4, "--egm-rotation"),
            "silence_sensor_after": silence_sensor_after, "silence_robot_after": silence_robot_after,
        }
        facility = start_facility(resolved, options)
    _stop_on_signals()
    a = facility.addresses
    f = resolved.facility
    sensor = facility.status()["sensor_protocol"]
    click.echo(
        f"ready: facility {resolved.name}: sensor {sensor} {_sensor_scheme(sensor)}://{a['sensor']}, "
        f"netftapi2.xml {'http://' + str(a['http']) + '/netftapi2.xml' if a['http'] else 'off'}, "
        f"robot {facility.status()['robot_protocol']} udp://{a['robot']} -> udp://{a['robot_peer']}; robot delay {f.robot_delay * 1e3:g} ms, "
        f"sensor delay {f.sensor_delay * 1e3:g} ms, noise {f.sensor_noise:g} N; Ctrl-C stops",
        nl=True,
    )
    import sys

    sys.stdout.flush()
    stderr = Console(stderr=True)
    try:
        with stderr.status("facility starting ...") as status:
            while duration is None or facility.status()["time"] < duration:
                time.sleep(0.1)
                status.update(_facility_line(facility.status()))
    except KeyboardInterrupt:
        pass
    final = facility.stop()
    click.echo("stopped: " + _facility_line(final))
    click.echo("endpoints: " + _facility_errors(final))


_SCHEDULING_OPTIONS = [
    click.option("--rt-priority", type=click.IntRange(0, 99), default=None, metavar="N",
                 help="SCHED_FIFO priority of the loop thread, 1-99 (0 = normal scheduling); a refusal by the OS is reported, not an error (docs/realtime.md)." + _dflt("runtime", "scheduling.priority")),
    click.option("--no-lock-memory", is_flag=True, default=False, help="Do not lock the process's memory (mlockall) [default: locked]."),
    click.option("--cpu", type=click.IntRange(min=0), default=None, metavar="N", help="Pin the loop thread to this CPU (0-based) [default: any CPU]."),
]


def _scheduling_options(rt_priority: int | None, no_lock_memory: bool, cpu: int | None) -> dict[str, Any] | None:
    """``{"scheduling": ...}``'s value from the CLI flags (None: the Rust defaults)."""
    scheduling = {k: v for k, v in (("priority", rt_priority), ("cpu", cpu)) if v is not None}
    if no_lock_memory:
        scheduling["lock_memory"] = False
    return scheduling or None


_HIL_OPTIONS = [
    _protocol_option("sensor", "runtime"),
    _protocol_option("robot", "runtime"),
    click.option("--sensor", "sensor_host", default=None, metavar="HOST", help="Host of the F/T sensor (Net F/T)." + _dflt("runtime", "sensor.host")),
    click.option("--sensor-port", type=PORT, default=None, help="RDT port of the sensor." + _dflt("runtime", "sensor.port")),
    click.option("--http-port", type=PORT, default=None, help="HTTP port of the sensor's /netftapi2.xml." + _dflt("runtime", "sensor.http_port")),
    click.option("--counts-per-force", type=NUMBER, default=None, help="Counts per N; with --counts-per-torque, /netftapi2.xml is not read."),
    click.option("--counts-per-torque", type=NUMBER, default=None, help="Counts per N m."),
    click.option("--rdt-local-port", type=PORT, default=None, help="Local UDP port of the RDT client (0 = any)." + _dflt("runtime", "sensor.local_port")),
    click.option("--bias", is_flag=True, default=None, help="Bias the sensor (RDT 0x0042) before streaming; the rod must be free."),
    click.option("--egm-port", type=PORT, default=None, help="UDP port the robot sends EGM feedback to." + _dflt("runtime", "robot.port")),
    click.option("--egm-bind", "egm_bind_host", default=None, metavar="HOST", help="Address the EGM endpoint binds to." + _dflt("runtime", "robot.bind_host")),
    click.option("--robot", "robot_host", default=None, metavar="HOST", help="Accept robot feedback (EGM, RSI) only from this host [default: the first sender whose feedback is at the scenario's start (within --start-tolerance)]."),
    click.option("--extrapolation", type=click.Choice(["quadratic", "linear", "hold"]), default=None, help="Actual motion between EGM feedback messages." + _dflt("runtime", "extrapolation")),
    click.option("--force-limit", type=NUMBER, default=None, help="Safety stop above this measured force." + _dflt("runtime", "limits.force_limit", "N")),
    click.option("--moment-limit", type=NUMBER, default=None, help="Safety stop above this measured moment." + _dflt("runtime", "limits.moment_limit", "N m")),
    click.option("--watchdog-ms", type=NUMBER, default=None, help="Safety stop after this long without sensor records or robot feedback." + _dflt("runtime", "limits.watchdog_ms", "ms")),
    click.option("--workspace", type=NUMBER, default=None, help="Safety stop when the commanded rod tip is this far from its start." + _dflt("runtime", "limits.workspace", "m")),
    click.option("--hold-deviation", type=NUMBER, default=None, help="A stop holds the robot at its fed-back pose only within this distance of the last command (else at the last command)." + _dflt("runtime", "limits.hold_deviation", "m")),
    click.option("--retreat-speed", type=NUMBER, default=None, help="After a force or moment stop, back away to the last contact-free pose at this speed." + _dflt("runtime", "limits.retreat_speed", "m/s")),
    click.option("--retreat-distance", type=NUMBER, default=None, help="Longest retreat after a force or moment stop." + _dflt("runtime", "limits.retreat_distance", "m")),
    click.option("--tracking-limit", type=NUMBER, default=None, help="Safety stop when the fed-back rod tip is this far from every command of the tracking window (frozen feedback, a robot that does not follow)." + _dflt("runtime", "limits.tracking_limit", "m")),
    click.option("--tracking-window", type=NUMBER, default=None, help="How far back commands are compared with the feedback (longer than the robot's delay)." + _dflt("runtime", "limits.tracking_window", "s")),
    click.option("--offset", "offset_mode", type=click.Choice(["measure", "off"]), default=None, help="The sensor's offset at start: measured with the rod free (nothing commanded) and subtracted, or used as it comes." + _dflt("runtime", "offset.mode")),
    click.option("--offset-time", type=NUMBER, default=None, help="How long the offset is averaged at start." + _dflt("runtime", "offset.time", "s")),
    click.option("--max-offset-force", type=NUMBER, default=None, help="Refuse the start when the force offset is larger (the rod may touch something)." + _dflt("runtime", "offset.max_force", "N")),
    click.option("--max-offset-moment", type=NUMBER, default=None, help="Refuse the start when the moment offset is larger." + _dflt("runtime", "offset.max_moment", "N m")),
    click.option("--connect-timeout", type=_Number(min=0.0, max=3600.0, min_open=True), default=None, help="Longest wait for the sensor and the robot." + _dflt("runtime", "connect_timeout", "s")),
    click.option("--start-tolerance", type=NUMBER, default=None, help="Largest distance of the robot from the initial pose at start." + _dflt("runtime", "start_tolerance", "m")),
    *_SCHEDULING_OPTIONS,
    *_link_option_flags("runtime"),
]


def _runtime_options(sensor_protocol: str | None, robot_protocol: str | None, sensor_host: str | None, sensor_port: int | None, http_port: int | None,
                     counts_per_force: float | None, counts_per_torque: float | None, rdt_local_port: int | None,
                     bias: bool | None, egm_port: int | None, egm_bind_host: str | None, robot_host: str | None,
                     extrapolation: str | None, force_limit: float | None, moment_limit: float | None,
                     watchdog_ms: float | None, workspace: float | None, hold_deviation: float | None,
                     retreat_speed: float | None, retreat_distance: float | None, tracking_limit: float | None,
                     tracking_window: float | None, offset_mode: str | None, offset_time: float | None,
                     max_offset_force: float | None, max_offset_moment: float | None, connect_timeout: float | None, start_tolerance: float | None, egm_offset: str | None,
                     egm_rotation: str | None, rt_priority: int | None, no_lock_memory: bool, cpu: int | None,
                     robot_port: int | None, sensor_options: tuple[str, ...], robot_options: tuple[str, ...]) -> dict[str, Any]:
    limits = {k: v for k, v in (("force_limit", force_limit), ("moment_limit", moment_limit),
                                ("watchdog_ms", watchdog_ms), ("workspace", workspace),
                                ("hold_deviation", hold_deviation), ("retreat_speed", retreat_speed),
                                ("retreat_distance", retreat_distance), ("tracking_limit", tracking_limit),
                                ("tracking_window", tracking_window)) if v is not None}
    offset = {k: v for k, v in (("mode", offset_mode), ("time", offset_time), ("max_force", max_offset_force),
                                ("max_moment", max_offset_moment)) if v is not None}
    # the flags keep their flat keys; hilcontact.realtime.LEGACY_KEYS moves them into the links
    return {
        "offset": offset or None,
        "scheduling": _scheduling_options(rt_priority, no_lock_memory, cpu),
        **_link_groups(sensor_protocol, robot_protocol, robot_port, sensor_options, robot_options),
        "sensor_host": sensor_host, "sensor_port": sensor_port, "http_port": http_port,
        "counts_per_force": counts_per_force, "counts_per_torque": counts_per_torque,
        "rdt_local_port": rdt_local_port, "bias": bias, "egm_port": egm_port, "egm_bind_host": egm_bind_host,
        "robot_host": robot_host, "extrapolation": extrapolation, "limits": limits or None,
        "connect_timeout": connect_timeout, "start_tolerance": start_tolerance,
        "egm_offset_mm": _numbers(egm_offset, 3, "--egm-offset"), "egm_rotation": _numbers(egm_rotation, 4, "--egm-rotation"),
    }


def _run_realtime(resolved: Any, options: dict[str, Any], folder: Path, no_plots: bool, force: bool,
                  mcap: Path | None = None) -> None:
    from .realtime import exit_code, run_hil

    if mcap is not None:
        options = {**options, "mcap": {"path": str(mcap), "overwrite": force}}
    _stop_on_signals()
    stderr = Console(stderr=True)
    with stderr.status(f"{escape(resolved.name)}: connecting to the sensor and the robot ...") as status:
        result = run_hil(resolved, options, on_status=lambda s: status.update(escape(_hil_line(s))))
    result.save(folder, plots=not no_plots, overwrite=force)
    console = Console()
    _report(console, result, folder)
    _report_realtime(console, result)
    _report_mcap(console, result.mcap)
    code = exit_code(result)
    if code:
        raise click.exceptions.Exit(code)


@cli.command(name="hil", short_help="Run the HIL loop in real time against a facility (real or emulated).")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@_with(_HIL_OPTIONS + _MAPPING_OPTIONS)
@click.option("--out", "out", metavar="DIR", default=None, help="Output folder [default: runs/<scenario name>-rt].")
@click.option("--no-plots", is_flag=True, help="Do not write the PNG figures.")
@click.option("--mcap", "mcap", metavar="FILE", default=None, help=_MCAP_HELP)
@click.option("--force", is_flag=True, help=_FORCE_HELP + " Replace --mcap FILE.")
@_with(_LIMIT_OPTIONS)
def hil_command(scenario: str, sets: tuple[str, ...], out: str | None, no_plots: bool, mcap: str | None, force: bool,
                max_memory: float, max_time: float, **kw: Any) -> None:
    """Run the HIL loop of SCENARIO in real time: RDT client of the F/T sensor at --sensor,
    EGM endpoint on UDP --egm-port for the robot controller, the scenario's compensator and
    virtual dynamics in a Rust real-time thread. Shows a live line; writes the same files as
    `run` (metrics.json with a "realtime" section: timing statistics, packet counters, stop,
    and the loop thread's scheduling: SCHED_FIFO --rt-priority, locked memory, --cpu, each
    granted or refused by the OS; a refusal is reported, the run goes on).

    Exit code: 0 completed, 3 safety stop (force/moment limit, watchdog, workspace, divergence;
    the robot is commanded to hold, streaming stops, the run is saved), 130 Ctrl-C (same),
    1 facility unreachable, 2 bad input.

    \b
    Example, against `hilcontact facility paper-table1 --set facility.robot_delay=0.02 --http-port 8080`:
      hilcontact hil paper-table1 --set compensator.kind=pida --sensor 127.0.0.1 --http-port 8080 --egm-port 6510 --out runs/rt1
    """
    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
        check_run(resolved, Limits(max_memory, max_time))
        folder = _out_folder(out, Path("runs") / f"{resolved.name}-rt", force)
        mcap_path = _mcap_file(mcap, folder, force)
        _run_realtime(resolved, _runtime_options(**kw), folder, no_plots, force, mcap_path)


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


@cli.command(name="check", short_help="Dry run: connect to the sensor and the robot as `hil` would, command nothing, report.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@_with(_HIL_OPTIONS + _MAPPING_OPTIONS)
@click.option("--duration", type=_Number(min=0.0, max=3600.0, min_open=True), default=1.0, show_default=True, metavar="S", help="How long to listen to the sensor and the robot, s.")
@click.option("--out", "out", metavar="DIR", default=None, help="Write check.json (the report) to this folder.")
def check_command(scenario: str, sets: tuple[str, ...], duration: float, out: str | None, **kw: Any) -> None:
    """Check that `hilcontact hil SCENARIO` with the same options would start, commanding
    nothing: connect to the sensor and the robot exactly as `hil` would, listen for --duration
    seconds, and report the sensor (rate, counters, counts per unit and units, the offset and
    the noise with the rod free) and the robot (the address locked onto, feedback rate,
    counters, the rod tip's distance from the scenario's start), then the verdict with the run's
    own reasons. The robot is sent nothing at all, not even a hold.

    Exit code: 0 a run would start, 1 it would refuse (or a link cannot be opened), 2 bad input.

    \b
    Example, against `hilcontact facility paper-table1 --http-port 8080`:
      hilcontact check paper-table1 --sensor 127.0.0.1 --http-port 8080 --egm-port 6510
    """
    from .realtime import check

    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
        folder = Path(out) if out is not None else None
        if folder is not None and folder.exists() and not folder.is_dir():
            raise ScenarioError(f"--out {folder}: exists and is not a directory")
        with Console(stderr=True).status(f"{escape(resolved.name)}: listening to the sensor and the robot for {duration:g} s ..."):
            report = check(resolved, _runtime_options(**kw), duration)
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "check.json").write_text(json.dumps(report, indent=2) + "\n")
    _report_check(Console(), report)
    if not report["would_start"]:
        raise click.exceptions.Exit(1)


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _demo_options(sensor_protocol: str | None, robot_protocol: str | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """Emulator and runtime options that meet on loopback on free ports, grouped per device
    (every protocol's options have a ``port``; RDT also an HTTP port for /netftapi2.xml)."""
    defaults = _RT_DEFAULTS.get("facility", {})
    sensor_kind = sensor_protocol or defaults.get("sensor", {}).get("kind", "rdt")
    robot_kind = robot_protocol or defaults.get("robot", {}).get("kind", "egm")
    sensor_socket = socket.SOCK_STREAM if _sensor_scheme(sensor_kind) == "tcp" else socket.SOCK_DGRAM
    sensor = {"kind": sensor_kind, "port": _free_port(sensor_socket)}
    robot = {"kind": robot_kind, "port": _free_port(socket.SOCK_DGRAM)}
    if sensor_kind == "rdt":
        sensor["http_port"] = _free_port(socket.SOCK_STREAM)
    facility = {"sensor": dict(sensor), "robot": dict(robot)}
    runtime = {"sensor": dict(sensor), "robot": {**robot, "bind_host": "127.0.0.1"}}
    return facility, runtime


@cli.command(name="demo-rt", short_help="Emulated facility and real-time HIL loop together, in one command.")
@click.argument("scenario", default="paper-table1")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@click.option("--compensator", default="pida", show_default=True, help="Compensator kind of the loop (none shows the safety stop).")
@click.option("--robot-delay", type=NON_NEGATIVE, default=0.02, show_default=True, help="The emulated robot's response delay, s.")
@_protocol_option("sensor", "facility")
@_protocol_option("robot", "facility")
@_with(_SCHEDULING_OPTIONS)
@click.option("--out", "out", metavar="DIR", default=None, help="Output folder [default: runs/<scenario name>-demo-rt].")
@click.option("--no-plots", is_flag=True, help="Do not write the PNG figures.")
@click.option("--mcap", "mcap", metavar="FILE", default=None, help=_MCAP_HELP)
@click.option("--force", is_flag=True, help=_FORCE_HELP + " Replace --mcap FILE.")
@_with(_LIMIT_OPTIONS)
def demo_rt(scenario: str, sets: tuple[str, ...], compensator: str, robot_delay: float, sensor_protocol: str | None,
            robot_protocol: str | None, rt_priority: int | None, no_lock_memory: bool, cpu: int | None,
            out: str | None, no_plots: bool, mcap: str | None, force: bool, max_memory: float, max_time: float) -> None:
    """Run the emulated facility and the real-time HIL loop on loopback in one process (free
    ports, HTTP included): `hilcontact facility` and `hilcontact hil` together.

    \b
    Examples:
      hilcontact demo-rt                                  # paper-table1, 20 ms robot delay, pida
      hilcontact demo-rt --compensator none               # diverges; the force limit stops it
    """
    from .realtime import start_facility

    with _errors():
        overrides = parse_set_options(sets)
        overrides.setdefault("facility.robot_delay", robot_delay)
        overrides["compensator.kind"] = compensator
        facility_options, runtime_options = _demo_options(sensor_protocol, robot_protocol)
        kinds = _RT_DEFAULTS.get("kinds", {})
        robot_kind = facility_options["robot"]["kind"]
        if robot_kind in kinds.get("robot_paced", []) and "simulation.period" not in overrides:
            # the robot's packets clock the loop (KUKA RSI): the scenario runs at its cycle
            overrides["simulation.period"] = kinds["facility"]["robot"][robot_kind]["period"]
        resolved = load_scenario(scenario, overrides)
        check_run(resolved, Limits(max_memory, max_time))
        folder = _out_folder(out, Path("runs") / f"{resolved.name}-demo-rt", force)
        mcap_path = _mcap_file(mcap, folder, force)
        scheduling = _scheduling_options(rt_priority, no_lock_memory, cpu)
        if scheduling:
            runtime_options["scheduling"] = scheduling
        with start_facility(resolved, facility_options) as facility:
            a = facility.addresses
            Console(stderr=True).print(
                f"facility: sensor {_sensor_scheme(facility_options['sensor']['kind'])}://{a['sensor']}{', http://' + str(a['http']) + '/netftapi2.xml' if a['http'] else ''}, "
                f"robot udp://{a['robot']} -> udp://{a['robot_peer']}",
                soft_wrap=True,
            )
            try:
                _run_realtime(resolved, runtime_options, folder, no_plots, force, mcap_path)
            finally:
                final = facility.stop()
                if final.get("io_errors"):
                    Console(stderr=True).print("facility " + escape(_facility_errors(final)), soft_wrap=True)


def main(argv: Sequence[str] | None = None) -> None:
    """Console-script entry point."""
    cli.main(args=list(argv) if argv is not None else None, prog_name="hilcontact")


# ---- your own data: replay and identify (hilcontact.recording) ------------------------------

_LOG_HELP = ("LOG: a run folder, a .csv or .parquet file with the recording's columns, or a ROS 2 bag "
             "folder (metadata.yaml). See README, 'Your own data'.")


def _recording_options(f: Any) -> Any:
    for option in reversed([
        click.option("--scenario", "scenario", metavar="FILE", default=None,
                     help="Scenario (preset or TOML) for the geometry and the compensator [default: a run folder's own, else paper-table1]."),
        click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP),
        click.option("--wrench-topic", default=None, help="ROS 2 bag: the geometry_msgs/WrenchStamped topic (sensor frame)."),
        click.option("--pose-topic", default=None, help="ROS 2 bag: the geometry_msgs/PoseStamped topic of the rod tip (frame t)."),
        click.option("--twist-topic", default=None, help="ROS 2 bag: a geometry_msgs/TwistStamped topic of the rod tip [default: differentiate the pose]."),
        click.option("--out", "out", metavar="DIR", required=True, help="Output folder."),
        click.option("--force", is_flag=True, help=_FORCE_HELP),
    ]):
        f = option(f)
    return f


@cli.command(name="replay", short_help="Run a compensator on a recording's measurements and poses.")
@click.argument("log")
@click.option("--compensator", "compensator", default=None, metavar="KIND", help="Compensator kind [default: the scenario's].")
@click.option("--desired-pose-topic", default=None, help="ROS 2 bag: a geometry_msgs/PoseStamped topic of the desired (virtual) rod tip (frame t).")
@_recording_options
def replay_command(log: str, compensator: str | None, desired_pose_topic: str | None, scenario: str | None,
                   sets: tuple[str, ...], wrench_topic: str | None, pose_topic: str | None,
                   twist_topic: str | None, out: str, force: bool) -> None:
    """Replay LOG through a compensator (open loop) and write what it would have applied at
    each tick: replay.parquet (time, applied_force_*, applied_moment_* in the sensor frame,
    velocity_correction_*, stiffness_estimate, damping_estimate, observed_energy),
    summary.json, scenario.toml. Tune with --set compensator.KEY=VALUE.

    \b
    Example:
      hilcontact run paper-table1 --set compensator.kind=pida --out runs/p
      hilcontact replay runs/p --out runs/p-replay --set compensator.forgetting=0.95
    """
    from .recording import DESIRED_COLUMNS, IDENTIFY_COLUMNS, read_recording, replay, save_replay

    with _errors():
        overrides = parse_set_options(sets)
        if compensator is not None:
            overrides["compensator.kind"] = compensator
        check_output_folder(out, overwrite=force)
        recording = read_recording(log, scenario, overrides, wrench_topic, pose_topic, twist_topic,
                                   need=IDENTIFY_COLUMNS + DESIRED_COLUMNS, desired_pose_topic=desired_pose_topic)
        summary = save_replay(recording, replay(recording), out, force)
    diff = summary.get("max_relative_difference_to_recorded")
    click.echo(f"{summary['compensator']}: {summary['samples']} ticks replayed -> {out}"
               + (f" (largest difference to the recorded applied wrench: {diff:.3g} of its peak)" if diff is not None else ""))


@cli.command(name="identify", short_help="Identify each collision's stiffness, damping and wall from a recording.")
@click.argument("log")
@click.option("--forgetting", type=float, default=0.9, show_default=True,
              help="Forgetting factor b of the filter's noise estimate (the compensators use 0.98; see docs/identification.md).")
@_recording_options
def identify_command(log: str, forgetting: float, scenario: str | None, sets: tuple[str, ...],
                     wrench_topic: str | None, pose_topic: str | None, twist_topic: str | None,
                     out: str, force: bool) -> None:
    """Identify, per collision of LOG, the contact stiffness and damping (the compensators'
    identification: the Sage-Husa filter with the sensor-delay alignment, restarted per
    collision) and the wall (point and normal), each with an uncertainty. Writes
    identification.parquet (per tick), collisions.csv, collisions.json, scenario.toml.

    \b
    Example:
      hilcontact identify runs/p --out runs/p-id
      hilcontact identify log.csv --scenario my.toml --out id
      hilcontact identify bag/ --wrench-topic /ft --pose-topic /tip --out id
    """
    from .recording import identify, read_recording, save_identification

    if not 0.0 < forgetting < 1.0:
        _fail(f"--forgetting {forgetting}: must be between 0 and 1 (exclusive)", 2)
    with _errors():
        check_output_folder(out, overwrite=force)
        recording = read_recording(log, scenario, parse_set_options(sets), wrench_topic, pose_topic, twist_topic)
        ticks, collisions = identify(recording, forgetting)
        save_identification(recording, ticks, collisions, out, force)
    console = Console()
    table = Table(title=f"{log}: {len(collisions)} collision(s)")
    for name in ("#", "start s", "k N/mm", "c N·s/mm", "normal", "±deg", "point mm", "±mm"):
        table.add_column(name, justify="right")
    for _, c in collisions.iterrows():
        table.add_row(
            str(int(c["index"])), f"{c['start']:.3f}",
            f"{c['stiffness'] / 1e3:.3f} ± {c['stiffness_std'] / 1e3:.3f}",
            f"{c['damping'] / 1e3:.4f} ± {c['damping_std'] / 1e3:.4f}",
            f"({c['normal_x']:.4f}, {c['normal_y']:.4f}, {c['normal_z']:.4f})", f"{c['normal_std_deg']:.3g}",
            f"({c['point_x'] * 1e3:.2f}, {c['point_y'] * 1e3:.2f}, {c['point_z'] * 1e3:.2f})", f"{c['offset_std'] * 1e3:.3g}",
        )
    console.print(table)
