"""The batch commands: ``run``, ``plot``, ``compare``, ``sweep``, ``stability-map``,
``presets``, ``init``, ``show``, and those on your own data, ``replay`` and ``identify``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click
from rich.console import Console
from rich.markup import escape

from ..comparison import ALL_KINDS, Comparison, comparison_scenarios, run_comparison
from ..errors import HilContactError, ScenarioError
from ..limits import Limits, check_run
from ..output import OutputError, check_output_folder, note_written
from ..run import Run, RunInterrupted, simulate
from ..scenario import load_scenario, presets
from .live import live_flags, live_settings
from .calibrate import CALIBRATION_OPTION, with_calibration
from .options import (
    _FORCE_HELP,
    _LIMIT_OPTIONS,
    _SET_HELP,
    NON_NEGATIVE,
    POSITIVE,
    _errors,
    _fail,
    _mcap_file,
    _out_folder,
    _stop_on_sigterm,
    _run_output_options,
    _with,
    cli,
    parse_set_options,
)
from .reports import (
    _report,
    _report_comparison,
    _report_identification,
    _report_mcap,
    _report_stability_map,
    _report_sweep,
)


def _compensators_option(help: str) -> Any:
    """``--compensators LIST`` (every kind by default)."""
    return click.option("--compensators", "kinds", metavar="LIST", default=",".join(ALL_KINDS), show_default=True,
                        help=help)


@cli.command(short_help="Simulate a scenario and save the results.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@_with(_run_output_options("runs/<scenario name>"))
@click.option("--compensator", "entry", default=None, metavar="FILE.py:CLASS",
              help="Run a compensator written in Python (path/to/file.py:ClassName or module:ClassName).")
@click.option("--step-limit", type=POSITIVE, default=None, metavar="S",
              help="Longest time one step of a Python compensator may take, s [default: 0.5].")
@_with(live_flags(replay=True))
@CALIBRATION_OPTION
def run(scenario: str, sets: tuple[str, ...], out: str | None, no_plots: bool, mcap: str | None, force: bool,
        max_memory: float, max_time: float, live: str | None, live_control: bool, live_remote: bool,
        live_wait: float, speed: float, entry: str | None = None, step_limit: float | None = None,
        calibration: str | None = None) -> None:
    """Simulate SCENARIO (a preset name or a TOML file) and save the results. With --live, the
    finished run is replayed to a Foxglove live view at --speed times real time (as a
    real-time run is shown), then saved."""
    _stop_on_sigterm()
    with _errors():
        resolved = load_scenario(scenario, with_calibration(parse_set_options(sets), calibration))
        check_run(resolved, Limits(max_memory, max_time))
        folder = _out_folder(out, Path("runs") / resolved.name, force)
        mcap_path = _mcap_file(mcap, folder, force)
        settings = live_settings(live, live_control, live_remote, live_wait, speed)
        outputs = {"live": settings} if settings else None
        before = _file_state(mcap_path)
        try:
            with Console(stderr=True).status(f"Simulating {escape(resolved.name)} ..."):
                result = simulate(resolved, mcap=mcap_path, overwrite=force, outputs=outputs, compensator=entry,
                                  step_limit=step_limit)
        except RunInterrupted as stopped:  # Ctrl-C during the simulation: the run so far is saved
            _save_interrupted(stopped, folder, mcap_path, force, no_plots)
        except KeyboardInterrupt:  # a second Ctrl-C: the part of a recording it wrote goes too
            if mcap_path is not None and _file_state(mcap_path) not in (before, None):
                mcap_path.unlink(missing_ok=True)
            raise
        if mcap_path is not None:
            note_written(mcap_path)
        result.save(folder, plots=not no_plots, overwrite=force)
    console = Console()
    _report(console, result, folder)
    _report_mcap(console, result.mcap)


def _save_interrupted(stopped: RunInterrupted, folder: Path, mcap_path: Path | None, force: bool,
                      no_plots: bool) -> None:
    """A run stopped by Ctrl-C: save it as it stands (its metrics say ``interrupted`` and at
    which time; no figures, ``hilcontact plot`` draws them), its MCAP recording up to there,
    then one ``interrupted: ...`` line naming what was saved, and exit code 130."""
    from ..output import written_folders
    from .options import EXIT_INTERRUPTED

    run = stopped.run
    if mcap_path is not None:
        note_written(mcap_path)
    run.save(folder, plots=False, overwrite=force)
    duration = run.scenario.simulation.duration
    when = (f"the run had finished ({run.status})" if run.status != "interrupted"
            else f"the simulation stopped at t = {stopped.time:.3f} s of {duration:g} s, saved as 'interrupted'")
    figures = "" if no_plots else f", no figures (hilcontact plot {folder} draws them)"
    saved = ", ".join(str(f) for f in written_folders())
    click.echo(f"interrupted: {when}{figures}; stopped after saving {saved}", err=True)
    raise click.exceptions.Exit(EXIT_INTERRUPTED)


def _file_state(path: Path | None) -> tuple[int, int, int] | None:
    """A file's identity and state (inode, size, modification time), None if it is not there:
    whether this process has written it since."""
    try:
        st = path.stat() if path is not None else None
    except OSError:
        return None
    return (st.st_ino, st.st_size, st.st_mtime_ns) if st is not None else None


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

    from ..output import marker_kind

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


@cli.command(name="compare", short_help="Run several compensators on one scenario and compare them.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
@_compensators_option("Comma-separated compensator kinds to run.")
@click.option(
    "--out", "out", metavar="DIR", default=None, help="Output folder [default: runs/<scenario name>-compare]."
)
@click.option("--no-plots", is_flag=True, help="Do not write the PNG figures.")
@click.option("--run-figures", is_flag=True, help="Also draw each compensator's own figures (slower; `hilcontact plot DIR` draws them later).")
@click.option("--force", is_flag=True, help=_FORCE_HELP)
@click.option("--delays", "delays", metavar="LIST", default=None,
              help="Compare at each robot delay (s, comma-separated, e.g. 0.01,0.02): a comparison folder per "
                   "delay and figures with one panel per delay, (a), (b), ….")
@_with(_LIMIT_OPTIONS)
@click.option("--compensator", "entries", multiple=True, metavar="FILE.py:CLASS",
              help="Also compare a compensator written in Python (path/to/file.py:ClassName); repeatable.")
@CALIBRATION_OPTION
def compare_command(scenario: str, sets: tuple[str, ...], kinds: str, out: str | None, no_plots: bool,
                    run_figures: bool, force: bool, delays: str | None, max_memory: float, max_time: float,
                    entries: tuple[str, ...] = (), calibration: str | None = None) -> None:
    """Simulate SCENARIO once per compensator and compare them: a ranking, a recommendation,
    and for each compensator that is not faithful the tolerance it broke (docs/choosing.md).

    Writes a run folder per compensator (data; its figures with --run-figures, or later with
    `hilcontact plot DIR/<compensator>`), comparison.md and comparison.csv (CoV, CoF, peak
    force, rebound speed, rebound velocity and direction errors, normal and tangential
    impulses and their errors per collision; status and identification errors per compensator)
    and the compare_*.png figures. With --delays, one such folder per delay (DIR/10ms/, …).
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    _stop_on_sigterm()
    if delays is not None:
        _compare_over_delays(scenario, sets, kinds, out, no_plots, run_figures, force, delays, max_memory, max_time,
                             calibration)
        return
    with _errors():
        overrides = with_calibration(parse_set_options(sets), calibration)
        scenarios = comparison_scenarios(scenario, kinds, overrides)  # validate all before running
        if entries:
            from ..plugin import with_python_compensators

            scenarios = with_python_compensators(scenarios, entries)
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


def _compare_over_delays(scenario: str, sets: tuple[str, ...], kinds: str, out: str | None, no_plots: bool,
                         run_figures: bool, force: bool, delays: str, max_memory: float, max_time: float,
                         calibration: str | None = None) -> None:
    """`compare --delays`: the comparison at each robot delay, saved and reported per delay."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from ..comparison import delay_label, delay_scenarios, parse_delays, run_over_delays

    with _errors():
        overrides = with_calibration(parse_set_options(sets), calibration)
        per_delay = delay_scenarios(scenario, parse_delays(delays), kinds, overrides)  # validate all first
        total = sum(len(per) for per in per_delay.values())
        first = next(iter(next(iter(per_delay.values())).values()))
        check_run(first, Limits(max_memory, max_time), runs=total)
        folder = _out_folder(out, Path("runs") / f"{first.name}-compare", force)
        with Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                      console=Console(stderr=True), transient=True) as progress:
            task = progress.add_task(f"Simulating {escape(first.name)}", total=total)

            def advance(label: str, index: int, count: int) -> None:
                progress.update(task, completed=index, description=f"Simulating {escape(first.name)}: {escape(label)}")

            result = run_over_delays(per_delay, progress=advance)
            progress.update(task, completed=total, description="Writing files")
            result.save(folder, plots=not no_plots, overwrite=force, run_plots=run_figures)
    console = Console()
    for delay, comparison in result.comparisons.items():
        _report_comparison(console, comparison, folder / delay_label(delay))
        console.print()
    console.print(f"saved to {escape(str(folder))}/ (comparison.md, one folder per delay"
                  + ("" if no_plots else ", compare_velocity.png, compare_force.png, compare_cov_cof.png with (a), (b), … panels")
                  + ")", soft_wrap=True)


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
@_compensators_option("Comma-separated compensator kinds to run at every grid point.")
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
@click.option("--compensator", "entries", multiple=True, metavar="FILE.py:CLASS",
              help="Also sweep a compensator written in Python (one run at a time per process; --dask spreads them); repeatable.")
@CALIBRATION_OPTION
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
    entries: tuple[str, ...] = (),
    calibration: str | None = None,
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

    from ..sweep import check_run_arguments, check_sweep_folder, plan_sweep, run_plan

    _stop_on_sigterm()
    with _errors():
        check_run_arguments(out, resume, dask, None, None, 5.0)
        overrides = with_calibration(parse_set_options(sets), calibration)
        # validate before anything runs
        plan = plan_sweep(scenario, list(grids), kinds, seeds, overrides, limits=Limits(max_memory, max_time),
                          threads=threads, python=list(entries))
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
            from ..sweep import RESULTS_FILE, _write_parquet_atomically, load_results

            try:
                finished = load_results(out)
                saved = len(finished)
                if saved and not (Path(out) / RESULTS_FILE).is_file():
                    # the interrupt came before the sweep merged its parts: merge them now, so
                    # that the file this line names holds what it says
                    _write_parquet_atomically(finished, Path(out) / RESULTS_FILE)
            except HilContactError:
                saved = 0
            click.echo(
                f"interrupted: {saved} finished run(s) saved in {out}/results.parquet; "
                "rerun with --resume to continue",
                err=True,
            )
            raise click.exceptions.Exit(130) from None
    _report_sweep(Console(), rows, out)


@cli.command(name="stability-map", short_help="Map where each compensator stays faithful in a sweep.")
@click.argument("sweep_dir", metavar="SWEEP_DIR")
@click.option("--out", "out", metavar="DIR", default=None, help="Output folder [default: SWEEP_DIR].")
@click.option("--cov-tolerance", default=None, type=NON_NEGATIVE,
              help="Stricter than the runs' verdicts: |CoV - 1| <= this on every collision.")
@click.option("--cof-limit", default=None, type=POSITIVE, help="Stricter than the runs' verdicts: CoF <= this on every collision.")
@click.option("--tolerate", default=1, show_default=True, type=click.IntRange(0, None),
              help="Failing runs (seeds) a faithful cell may hold, while they are fewer than half of it; 0: every run.")
def stability_map_command(sweep_dir: str, out: str | None, cov_tolerance: float | None, cof_limit: float | None,
                          tolerate: int) -> None:
    """Draw, per compensator, the fraction of faithful runs (seeds) of each (contact
    frequency, robot delay) cell (a run is faithful with status ok: the scenario's [metrics]
    tolerances, from judge_from on; a cell is faithful when all its runs but at most
    --tolerate are, the failing ones fewer than half), heat maps of the worst CoV and CoF,
    and print the faithful runs per cell and the maximal faithful delay per compensator and
    contact frequency.

    Writes stability_map.png, worst_cov.png, worst_cof.png, max_faithful_delay.csv and
    cells.csv into DIR.
    """
    from ..stability import MAP_FILES, criterion_text, stability_map

    with _errors():
        if not Path(sweep_dir).is_dir():
            raise ScenarioError(f"{sweep_dir}: not a sweep folder")
        result = stability_map(sweep_dir, cov_tolerance=cov_tolerance, cof_limit=cof_limit, tolerate=tolerate)
        folder = result.save(out if out is not None else sweep_dir)
    _report_stability_map(Console(), result, folder, criterion_text(cov_tolerance, cof_limit), MAP_FILES)


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
    from ..template import write_template

    with _errors():
        resolved = load_scenario(source, parse_set_options(sets))
        written = write_template(file, resolved, overwrite=force)
    click.echo(f"wrote {written} (from {source}); run it with: hilcontact run {written}")


@cli.command(short_help="Print a scenario's resolved TOML.")
@click.argument("scenario")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP)
def show(scenario: str, sets: tuple[str, ...]) -> None:
    """Print the resolved TOML of SCENARIO (a preset name or a TOML file)."""
    with _errors():
        resolved = load_scenario(scenario, parse_set_options(sets))
    click.echo(resolved.to_toml(), nl=False)


# ---- your own data: replay and identify (hilcontact.recording) ------------------------------

#: The options of ``replay`` and ``identify``: the scenario, the bag's topics, the output folder.
_RECORDING_OPTIONS = [
    click.option("--scenario", "scenario", metavar="FILE", default=None,
                 help="Scenario (preset or TOML) for the geometry and the compensator [default: a run folder's own, else paper-table1]."),
    click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=_SET_HELP),
    click.option("--wrench-topic", default=None, help="ROS 2 bag: the geometry_msgs/WrenchStamped topic (sensor frame)."),
    click.option("--pose-topic", default=None, help="ROS 2 bag: the geometry_msgs/PoseStamped topic of the rod tip (frame t)."),
    click.option("--twist-topic", default=None, help="ROS 2 bag: a geometry_msgs/TwistStamped topic of the rod tip [default: differentiate the pose]."),
    click.option("--out", "out", metavar="DIR", required=True, help="Output folder."),
    click.option("--force", is_flag=True, help=_FORCE_HELP),
]


@cli.command(name="replay", short_help="Run a compensator on a recording's measurements and poses.")
@click.argument("log")
@click.option("--compensator", "compensator", default=None, metavar="KIND",
              help="Compensator kind, or one written in Python (FILE.py:CLASS) [default: the scenario's].")
@click.option("--desired-pose-topic", default=None, help="ROS 2 bag: a geometry_msgs/PoseStamped topic of the desired (virtual) rod tip (frame t).")
@_with(_RECORDING_OPTIONS)
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
    from ..recording import DESIRED_COLUMNS, IDENTIFY_COLUMNS, read_recording, replay, save_replay

    with _errors():
        overrides = parse_set_options(sets)
        python = compensator is not None and ":" in compensator
        if python:
            overrides.update({"compensator.kind": "python", "compensator.entry": compensator})
        elif compensator is not None:
            overrides["compensator.kind"] = compensator
        check_output_folder(out, overwrite=force)
        recording = read_recording(log, scenario, overrides, wrench_topic, pose_topic, twist_topic,
                                   need=IDENTIFY_COLUMNS + DESIRED_COLUMNS, desired_pose_topic=desired_pose_topic)
        entry = recording.scenario.python_entry
        if entry is not None:
            from ..plugin import replay as replay_python

            table = replay_python(entry, recording.scenario, recording.data)
        else:
            table = replay(recording)
        summary = save_replay(recording, table, out, force)
    diff = summary.get("max_relative_difference_to_recorded")
    click.echo(f"{summary['compensator']}: {summary['samples']} ticks replayed -> {out}"
               + (f" (largest difference to the recorded applied wrench: {diff:.3g} of its peak)" if diff is not None else ""))


@cli.command(name="identify", short_help="Identify each collision's stiffness, damping and wall from a recording.")
@click.argument("log")
@click.option("--forgetting", type=float, default=0.9, show_default=True,
              help="Forgetting factor b of the filter's noise estimate (the compensators use 0.98; see docs/identification.md).")
@click.option("--columns", "columns", metavar="MAP", default=None,
              help="Map your own column names, signs and units, e.g. 'fx=Fx_N,px=x_mm:mm,fz=-Fz' "
                   "(keys t, fx.., mx.., px.., vx..; see docs/identification.md).")
@click.option("--unchecked", is_flag=True,
              help="Write the results even when a plausibility check fails (printed as warnings).")
@click.option("--no-plots", is_flag=True, help="Do not write the figures.")
@_with(_RECORDING_OPTIONS)
def identify_command(log: str, forgetting: float, columns: str | None, unchecked: bool, no_plots: bool,
                     scenario: str | None, sets: tuple[str, ...], wrench_topic: str | None, pose_topic: str | None,
                     twist_topic: str | None, out: str, force: bool) -> None:
    """Identify, per collision of LOG, the contact stiffness and damping (the compensators'
    identification: the Sage-Husa filter with the sensor-delay alignment, restarted per
    collision) and the wall (point and normal), each with an uncertainty. LOG: a run folder,
    a CSV or Parquet file, an MCAP file (--mcap of run/hil, or a ROS 2 bag in MCAP), a ROS 2
    bag folder. Checks that the result is plausible (force's sign, units, a stiffness that
    is positive, a wall near the poses) and refuses, naming the likely cause, when it is not.
    Writes identification.parquet (per tick), collisions.csv, collisions.json,
    scenario.toml and the figures identification.png (k and c over time) and
    force_penetration.png (force against penetration with the fitted law, per collision).

    \b
    Example:
      hilcontact identify runs/p --out runs/p-id
      hilcontact identify runs/rt1.mcap --out runs/rt1-id
      hilcontact identify log.csv --scenario my.toml --columns fz=-Fz,px=x_mm:mm --out id
      hilcontact identify bag/ --wrench-topic /ft --pose-topic /tip --out id
    """
    from ..recording import check_plausibility, identify, read_recording, save_identification

    if not 0.0 < forgetting < 1.0:
        _fail(f"--forgetting {forgetting}: must be between 0 and 1 (exclusive)", 2)
    console = Console(stderr=True)
    with _errors():
        check_output_folder(out, overwrite=force)
        recording = read_recording(log, scenario, parse_set_options(sets), wrench_topic, pose_topic, twist_topic,
                                   columns=columns)
        ticks, collisions = identify(recording, forgetting)
        findings = check_plausibility(recording, ticks, collisions)
        errors = [f for f in findings if f.level == "error"]
        if errors and not unchecked:
            raise ScenarioError(f"{log}: {errors[0].message}; --unchecked writes it anyway")
        save_identification(recording, ticks, collisions, out, force, plots=not no_plots)
    for note in recording.derived:
        console.print(f"note: {escape(note)}")
    for finding in findings:
        console.print(f"[yellow]warning:[/yellow] {escape(finding.message)}")
    _report_identification(Console(), str(log), collisions)
