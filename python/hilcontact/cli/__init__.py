"""The ``hilcontact`` command line.

    hilcontact run SCENARIO [--set KEY=VALUE ...] [--out DIR] [--no-plots] [--mcap FILE] [--live PORT [--speed X]]
    hilcontact compare SCENARIO [--set KEY=VALUE ...] [--compensators LIST] [--out DIR] [--no-plots] [--run-figures]
    hilcontact plot RUN_OR_COMPARISON_DIR
    hilcontact identify LOG --out DIR [--scenario FILE] [--wrench-topic T --pose-topic T ...]
    hilcontact replay LOG --compensator KIND [--set compensator.KEY=VALUE ...] --out DIR
    hilcontact sweep SCENARIO --grid KEY=START:STOP:COUNT|KEY=A,B,... [--compensators LIST]
                     [--seeds N] [--set KEY=VALUE ...] --out DIR [--resume] [--dask ADDRESS]
    hilcontact stability-map SWEEP_DIR [--out DIR] [--cov-tolerance 0.05] [--cof-limit 1.2]
    hilcontact benchmark [--compensators LIST] [--compensator FILE.py:CLASS ...] [--cases PATTERNS] [--out DIR] [--resume]
    hilcontact benchmark --compare A B
    hilcontact presets
    hilcontact init FILE.toml [--from PRESET] [--set KEY=VALUE ...]
    hilcontact show SCENARIO [--set KEY=VALUE ...]
    hilcontact facility SCENARIO [--sensor-port 49152 --http-port 80 --egm-host H --egm-port 6510 ...] [--live PORT --live-control]
    hilcontact hil SCENARIO --sensor HOST [--sensor-protocol rdt|sri --robot-protocol egm|rsi --robot-port N
                   --robot-option KEY=VALUE --force-limit N --rt-priority 80 --cpu N ...] [--out DIR] [--mcap FILE]
    hilcontact check SCENARIO --sensor HOST [the options of hil] [--duration 1] [--out DIR]
    hilcontact demo-rt [SCENARIO] [--compensator pida] [--rt-priority 80 --no-lock-memory --cpu N] [--out DIR] [--mcap FILE]
    hilcontact calibrate SCENARIO --out cal.toml --simulate [--set KEY=VALUE ...] [--option KEY=VALUE ...]
    hilcontact layout > hil.json
    hilcontact --version

Bad input (scenario, override, option, output folder) prints one ``error: ...`` line on stderr
and exits with code 2; nothing is written then. ``hil`` and ``demo-rt`` exit with 3 after a
safety stop and 130 after Ctrl-C (the run is saved in both cases); a facility that cannot be
reached or a port in use exits with 1. ``check`` exits with 0 when a run would start, 1 when it
would refuse. An interrupted sweep (Ctrl-C) keeps its finished rows
and exits with code 130.

Ctrl-C (or SIGTERM) at any other moment of a batch command, from its start-up (importing the
package: :mod:`hilcontact._startup`) to its last line, prints one ``interrupted: ...`` line
naming what it had completely saved, or saying that nothing was written, and exits with code
130; no traceback. A simulation stopped midway (``run``, with a shipped or a Python
compensator) is saved up to the tick it stopped at, as ``interrupted``; a second Ctrl-C
meanwhile saves nothing, nor the part of its ``--mcap`` recording; an output folder is never left half-replaced (:mod:`hilcontact.output`). A Ctrl-C during
Python's own start-up, before hilcontact's code runs, is Python's.
Two commands writing the same ``--out``: the last one wins and prints a ``note: ...`` line
when it replaced the other's folder.

The package: :mod:`.options` (the command group and the shared option machinery),
:mod:`.batch` (the simulation and offline commands), :mod:`.realtime_commands` (``hil``,
``check``, ``facility``, ``demo-rt``), :mod:`.reports` (what the commands print).
"""

from __future__ import annotations

from collections.abc import Sequence

from . import batch, live, realtime_commands  # noqa: F401  (each registers its commands on the group)
from . import bench  # noqa: F401  (registers benchmark)
from . import calibrate  # noqa: F401  (registers calibrate)
from .options import cli, parse_set_options

__all__ = ["cli", "main", "parse_set_options"]


def main(argv: Sequence[str] | None = None) -> None:
    """Console-script entry point."""
    cli.main(args=list(argv) if argv is not None else None, prog_name="hilcontact")
