"""``--calibration FILE`` of run, compare, sweep and hil: a calibration file
(``hilcontact calibrate``) read into ``compensator.calibration``. Apart from the command so that
the real-time commands can take the option and ``calibrate`` their flags."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import click

from ..errors import ScenarioError

__all__ = ["CALIBRATION_OPTION", "read_calibration", "with_calibration"]


def read_calibration(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A calibration file's tables (``[measured]``, ``[[walls]]``, ``[law]``, ``[robot]``), for
    ``compensator.calibration``; raises ScenarioError naming the file."""
    import tomllib

    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"--calibration {path}: {exc.strerror or exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"--calibration {path}: not a TOML file: {exc}") from None
    if not data.get("walls"):
        raise ScenarioError(f"--calibration {path}: no [[walls]]: not a calibration file")
    return data


def with_calibration(overrides: dict[str, Any], path: str | None) -> dict[str, Any]:
    """``overrides`` plus ``compensator.calibration`` from the calibration file at ``path``
    (for ``model-mediated``; none without a path)."""
    if path is None:
        return overrides
    return {**overrides, "compensator.calibration": read_calibration(path)}


#: ``--calibration FILE`` of run, compare, sweep and hil.
CALIBRATION_OPTION = click.option(
    "--calibration", "calibration", metavar="FILE", default=None,
    help="A calibration file (`hilcontact calibrate`): model-mediated renders its walls and law from the first contact "
         "(sets compensator.calibration).",
)
