"""The shared option machinery of the ``hilcontact`` commands: the command group (one
``error: ...`` line and exit code 2 for a usage error), ``--set KEY=VALUE`` parsing, number
types with ranges, the output folder and ``--mcap`` checks, and the mapping of errors to
exit codes."""

from __future__ import annotations

import math
import os
import signal
import sys
import threading
import tomllib
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import click

from .._startup import finishing, started
from ..errors import HilContactError, RealtimeOptionError, ScenarioError
from ..limits import Limits
from ..output import OutputError, ReplacedWhileRunning, check_output_folder, resolve_path, written_folders
from ..native import VERSION, core_version


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
        except ValueError:  # Python's limit on the digits of an integer (sys.get_int_max_str_digits)
            raise ScenarioError(
                f"--set {key}: a number of more than {sys.get_int_max_str_digits()} digits; "
                "give a number such as 0.02 or 1e30"
            ) from None
        overrides[key] = value
    return overrides


def _one_line(message: str) -> str:
    return "error: " + " ".join(message.split("\n"))


def _fail(message: str, code: int) -> None:
    click.echo(_one_line(message), err=True)
    raise click.exceptions.Exit(code)


class _Interrupted(Exception):
    """A command stopped by Ctrl-C (or SIGTERM, turned into KeyboardInterrupt): carried past
    click, which would print an empty line and "Aborted!", to :meth:`_Cli.main`."""


#: Exit code of a command stopped by Ctrl-C or SIGTERM (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130


def interrupted_line() -> str:
    """The one line a command stopped by Ctrl-C prints: what it had written (the folders it
    completed, :func:`hilcontact.output.written_folders`), or that it wrote nothing."""
    folders = written_folders()
    if not folders:
        return "interrupted: stopped before anything was saved; nothing written"
    return "interrupted: stopped after saving " + ", ".join(str(f) for f in folders)


class _Cli(click.Group):
    """The command group; a usage error (an unknown option, a bad option value, a missing
    argument) is one ``error: ...`` line on stderr and exit code 2, like every bad input; Ctrl-C
    (or SIGTERM in a batch command) is one ``interrupted: ...`` line (:func:`interrupted_line`)
    and exit code 130, whenever it comes."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt:
            raise _Interrupted() from None

    def main(self, *args: Any, standalone_mode: bool = True, **kwargs: Any) -> Any:
        started()
        if not standalone_mode:
            return super().main(*args, standalone_mode=False, **kwargs)
        try:
            code = self._exit_code(*args, **kwargs)
            finishing()  # from here on a Ctrl-C is ignored: the command is done
        except (_Interrupted, KeyboardInterrupt):
            _interrupted_exit()
        sys.exit(code)

    def _exit_code(self, *args: Any, **kwargs: Any) -> int | str | None:
        """Run the command; its exit code, after printing the one line of a usage error."""
        try:
            code = super().main(*args, standalone_mode=False, **kwargs)
        except click.Abort as exc:
            if isinstance(exc.__cause__, KeyboardInterrupt):
                raise _Interrupted() from None
            click.echo("Aborted!", err=True)
            return 1
        except click.UsageError as exc:
            command = exc.ctx.command_path + ": " if exc.ctx is not None and exc.ctx.parent is not None else ""
            click.echo(_one_line(command + exc.format_message()), err=True)
            return exc.exit_code
        except click.ClickException as exc:
            click.echo(_one_line(exc.format_message()), err=True)
            return exc.exit_code
        except EOFError:
            click.echo("Aborted!", err=True)
            return 1
        except SystemExit as exc:  # a command's own exit (sys.exit)
            return exc.code
        return code if isinstance(code, int) else 0


def _interrupted_exit() -> None:
    """Print :func:`interrupted_line` and exit with code 130; a second Ctrl-C meanwhile changes
    nothing."""
    finishing()
    try:
        click.echo(interrupted_line(), err=True)
        sys.stderr.flush()
    except (OSError, ValueError):
        pass
    sys.exit(EXIT_INTERRUPTED)


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


def _run_output_options(default_out: str) -> list[Any]:
    """The options of a command that runs a scenario and saves it (``run``, ``hil``,
    ``demo-rt``): ``--out DIR`` (``default_out`` shown as its default), ``--no-plots``,
    ``--mcap FILE``, ``--force``, then the limits."""
    return [
        click.option("--out", "out", metavar="DIR", default=None, help=f"Output folder [default: {default_out}]."),
        click.option("--no-plots", is_flag=True, help="Do not write the PNG figures."),
        click.option("--mcap", "mcap", metavar="FILE", default=None, help=_MCAP_HELP),
        click.option("--force", is_flag=True, help=_FORCE_HELP + " Replace --mcap FILE."),
        *_LIMIT_OPTIONS,
    ]


@contextmanager
def _errors() -> Iterator[None]:
    """Bad input (exit 2) and other errors (exit 1) as one ``error: ...`` line; a
    :class:`~hilcontact.output.ReplacedWhileRunning` warning as a ``note: ...`` line."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always", ReplacedWhileRunning)
            warnings.showwarning = _note  # type: ignore[assignment]
            yield
    except (ScenarioError, RealtimeOptionError, OutputError) as exc:
        _fail(str(exc), 2)
    except HilContactError as exc:
        _fail(str(exc), 1)
    except OSError as exc:  # a disk or permission error that no command turned into an OutputError
        where = f"{exc.filename}: " if exc.filename else ""
        _fail(f"{where}{exc.strerror or exc}", 2)


def _note(message: Warning | str, category: type[Warning], *_args: Any, **_kwargs: Any) -> None:
    """A warning as a ``note: ...`` line on stderr (inside :func:`_errors`)."""
    click.echo("note: " + " ".join(str(message).split("\n")), err=True)


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
    target = resolve_path(path, f"--mcap {mcap}")
    if target.is_dir():
        raise OutputError(f"--mcap {mcap}: is a directory; give a file name, e.g. --mcap run.mcap")
    out = resolve_path(folder, f"--out {folder}")
    if target == out or out in target.parents:
        raise OutputError(
            f"--mcap {mcap}: is inside --out {folder}, which is replaced as a whole when the run is saved; "
            "write it elsewhere"
        )
    if not target.parent.is_dir():  # no folder is created for it (issue 25)
        raise OutputError(f"--mcap {mcap}: its folder {target.parent} does not exist; create it first")
    if os.path.lexists(target) and not target.is_file():
        raise OutputError(f"--mcap {mcap}: exists and is not a file")
    if target.exists() and not force:
        raise OutputError(f"--mcap {mcap}: exists; choose another file, or add --force to replace it")
    return path


def _print_version(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    if not value or ctx.resilient_parsing:
        return
    click.echo(f"hilcontact {VERSION} (core {core_version() or 'not built'})")
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


def _raise_keyboard_interrupt(_signum: int, _frame: Any) -> None:
    raise KeyboardInterrupt


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
