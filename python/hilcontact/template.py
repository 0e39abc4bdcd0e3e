"""A scenario file to start from: every key of a scenario, each with a comment giving its
meaning, unit and default (``hilcontact init``).

The comments come from the scenario schema (:data:`hilcontact.scenario.SCHEMA`, the core's one
definition of every key), the values from a resolved scenario (a preset by default), so the
file loads back to exactly that scenario.
"""

from __future__ import annotations

import os
import re
import textwrap
import typing
from pathlib import Path
from typing import Any

from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from .errors import ScenarioError
from .output import OutputError
from .scenario import COMPENSATOR_MODELS, Scenario, _TABLES

__all__ = ["commented_toml", "write_template"]

#: ``[table]`` or ``[[table]]`` header lines of the resolved TOML.
_HEADER = re.compile(r"^\[\[?([A-Za-z_][A-Za-z0-9_.]*)\]\]?\s*$")
#: ``key = value`` lines (a value's continuation lines start with a space or a bracket).
_KEY = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*) = ")


def _default_text(value: Any) -> str:
    if value is PydanticUndefined:
        return "required"
    if isinstance(value, BaseModel):
        return "a table of its own, below"
    if isinstance(value, bool):
        return f"default {'true' if value else 'false'}"
    if isinstance(value, str):
        return f"default {value!r}" if value else "default empty"
    return f"default {value}"


def _comment(description: str | None, default: Any) -> list[str]:
    text = (description or "").strip()
    text = f"{text} [{_default_text(default)}]" if text else f"[{_default_text(default)}]"
    return ["# " + line for line in textwrap.wrap(text, width=96)]


def _models(table: str | None, compensator: str) -> Any:
    """The pydantic model of a table (the scenario's top level for None); a dotted name
    (``compensator.fallback``, ``compensator.prior_walls``) is a table inside a table."""
    if table is None:
        return Scenario
    if "." in table:
        parent, _, name = table.rpartition(".")
        owner = _models(parent, compensator)
        field = owner.model_fields.get(name) if owner is not None else None
        if field is None:
            return None
        annotation = field.annotation
        for inner in (annotation, *typing.get_args(annotation)):  # a model, or list[model]
            if isinstance(inner, type) and issubclass(inner, BaseModel):
                return inner
        return None
    model = _TABLES.get(table)
    if isinstance(model, dict):  # the compensator's table: the chosen kind's model
        return model[compensator]
    return model


def commented_toml(scenario: Scenario) -> str:
    """The scenario's resolved TOML (:meth:`Scenario.to_toml`) with a comment above every key:
    its description with unit, and its default or ``required``. Loading the text gives the
    same scenario."""
    compensator = scenario.compensator.kind
    kinds = ", ".join(COMPENSATOR_MODELS)
    lines = [
        f"# hilcontact scenario, from {scenario.name!r}: every key, with its meaning, unit and default.",
        "# SI units (m, s, N, N·m, kg, rad); frames and the contact law: docs/scenario.md and docs/model.md.",
        "# Run it: hilcontact run THIS_FILE    Override a key: --set facility.robot_delay=0.02",
        "",
    ]
    table: str | None = None
    described: set[str] = set()
    for line in scenario.to_toml().splitlines():
        if line.startswith("#"):
            continue  # to_toml's own header: replaced by the one above
        header = _HEADER.match(line)
        if header:
            table = header.group(1)
            model = _models(table, compensator)
            if lines[-1].strip():
                lines.append("")
            if model is not None and model.__doc__ and table not in described:
                lines += ["# " + w for w in textwrap.wrap(" ".join(model.__doc__.split()), width=96)]
            described.add(table)
            if table == "compensator":
                lines.append(f"# kind: one of {kinds}; each kind's parameters: docs/compensators/.")
            lines.append(line)
            continue
        key = _KEY.match(line)
        model = _models(table, compensator)
        if key and model is not None and key.group(1) in model.model_fields:
            field = model.model_fields[key.group(1)]
            lines += _comment(field.description, field.get_default(call_default_factory=True))
        if line.strip() or (lines and lines[-1].strip()):
            lines.append(line)
    return "\n".join(lines).rstrip("\n") + "\n"


def write_template(path: str | os.PathLike[str], scenario: Scenario, overwrite: bool = False) -> Path:
    """Write :func:`commented_toml` of ``scenario`` to ``path``: never over an existing file
    unless ``overwrite`` (:class:`~hilcontact.output.OutputError` then), through a temporary
    file renamed into place. Returns the path."""
    target = Path(path)
    if target.is_dir():
        raise OutputError(f"{target}: is a folder; give a file name such as my.toml")
    if target.exists() and not overwrite:
        raise OutputError(f"{target}: exists; choose another name or add --force to replace it")
    if target.suffix != ".toml":
        raise ScenarioError(f"{target}: a scenario file's name ends in .toml")
    text = commented_toml(scenario)
    temporary = target.with_name(f".{target.name}.tmp-{os.getpid()}")
    try:
        temporary.write_text(text, encoding="utf-8")
        os.replace(temporary, target)
    except OSError as exc:
        temporary.unlink(missing_ok=True)
        raise OutputError(f"{target}: cannot write: {exc.strerror or exc}") from None
    return target
