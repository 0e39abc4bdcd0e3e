"""``hilcontact benchmark``: score compensators on the suite ``hil-bench-1``
(:mod:`hilcontact.benchmark`), or put two benchmark folders side by side."""

from __future__ import annotations

from pathlib import Path

import click
from rich.console import Console

from .options import POSITIVE, _errors, _stop_on_sigterm, cli


@cli.command(name="benchmark", short_help="Score compensators on the benchmark suite hil-bench-1.")
@click.option("--compensators", "kinds", default=None, metavar="LIST",
              help="Comma-separated shipped compensator kinds [default: all, or none with --compensator].")
@click.option("--compensator", "entries", multiple=True, metavar="FILE.py:CLASS",
              help="A compensator written in Python (path/to/file.py:ClassName or module:ClassName); repeatable.")
@click.option("--cases", default=None, metavar="PATTERNS",
              help="Only the cases matching these comma-separated shell patterns (e.g. 'paper-*,grid-*-4hz-clean').")
@click.option("--out", "out", metavar="DIR", default=None, help="Benchmark folder [default: benchmarks/hil-bench-1].")
@click.option("--resume", is_flag=True, help="Continue the benchmark in --out, skipping its finished runs.")
@click.option("--threads", type=click.IntRange(1, 1024), default=None, help="Rust threads [default: one per core].")
@click.option("--step-limit", type=POSITIVE, default=None, metavar="S",
              help="Longest time one step of a Python compensator may take, s [default: 0.5].")
@click.option("--no-plots", is_flag=True, help="Do not draw pass_fraction.png.")
@click.option("--dask", default=None, metavar="ADDRESS",
              help="Run on Dask: 'local' (one worker process per core) or a scheduler address.")
@click.option("--compare", "compare", nargs=2, default=None, metavar="A B",
              type=click.Path(file_okay=False, path_type=Path),
              help="Put two benchmark folders side by side (runs nothing).")
def benchmark_command(kinds: str | None, entries: tuple[str, ...], cases: str | None, out: str | None,
                      resume: bool, threads: int | None, step_limit: float | None, no_plots: bool,
                      dask: str | None, compare: tuple[Path, Path] | None) -> None:
    """Run every case of hil-bench-1 with each compensator; write one file per finished run,
    results.csv, summary.csv, summary.md and pass_fraction.png to DIR. Ctrl-C keeps the
    finished runs; rerun with --resume to continue. With --compare A B, print the two folders'
    summaries and per-case verdicts side by side."""
    from ..benchmark import SUITE, compare_folders, run_benchmark, to_markdown

    console = Console()
    if compare is not None:
        with _errors():
            summaries, statuses = compare_folders(*compare)
        console.print(to_markdown(summaries), soft_wrap=True, markup=False)
        console.print(to_markdown(statuses), soft_wrap=True, markup=False)
        return
    _stop_on_sigterm()
    folder = Path(out) if out is not None else Path("benchmarks") / SUITE
    stderr = Console(stderr=True)
    with _errors():
        try:
            with stderr.status(f"{SUITE} ...") as status:
                summary = run_benchmark(
                    folder, kinds, list(entries), cases, resume=resume, threads=threads, step_limit=step_limit,
                    plots=not no_plots, dask=dask,
                    progress=lambda done, total: status.update(f"{SUITE}: {done}/{total} runs"),
                )
        except KeyboardInterrupt:
            click.echo(f"interrupted: the finished runs are in {folder}/cases; rerun with --resume to continue",
                       err=True)
            raise click.exceptions.Exit(130) from None
    console.print(f"# {SUITE}\n", markup=False)
    console.print(to_markdown(summary), soft_wrap=True, markup=False)
    console.print(f"wrote {folder}/summary.md, results.csv" + ("" if no_plots else ", pass_fraction.png"), markup=False)
