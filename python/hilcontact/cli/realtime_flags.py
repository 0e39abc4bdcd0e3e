"""The real-time flags, built from the JSON Schema of the real-time options
(``hilcontact._core.realtime_schema()``, written once in Rust): a new option is one field in
Rust and nothing here.

Each option of a section (``runtime``: the loop's, ``facility``: the emulator's) becomes one
flag: its type from the JSON type (a number, a whole number, a string, a choice, a fixed list
of numbers given as ``X,Y,Z``, a boolean as an on/off flag), its range from
``minimum``/``maximum`` (a number's lower bound, e.g. "> 0", is left to the Rust parse of the
options, whose message names the option's key as the messages of earlier versions did), its
help from the description and ``[default: ...]`` from the default. The options of a group (``limits``, ``offset``,
``scheduling``) are flags of their own; the per-protocol options of ``sensor`` and ``robot``
(the ``oneOf`` variants tagged by ``kind``) are one flag per option: ``--sensor-port`` for an
option every protocol of the link has, ``--rsi-deadline`` for one protocol's (which then
implies that protocol). Options of another shape (an object, a nested list) are set with
``--sensor-option``/``--robot-option KEY=VALUE``.

Names: ``--<option>`` at the top level and in ``limits``, ``--<group>-<option>`` in the other
groups, ``--<link>-<option>`` or ``--<protocol>-<option>`` for the links; the flags of earlier
versions keep their names through :data:`HISTORICAL_NAMES`, and where the flat option keys of
earlier versions (:data:`hilcontact.realtime.LEGACY_KEYS`) name the same option, the flag sets
that key, so that its messages stay as they were.
"""

from __future__ import annotations

import functools
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import click

from ..errors import HilContactError, RealtimeOptionError
from ..native import core
from ..realtime import ANY_KIND, LEGACY_KEYS
from .options import _Number, _numbers

__all__ = ["HISTORICAL_NAMES", "RealtimeFlag", "flags_from_schema", "options_from_flags"]

#: The links whose options are per protocol (``oneOf`` tagged by ``kind``).
LINKS = ("sensor", "robot")

#: Groups whose options are flags named by the option alone (``--force-limit``).
UNPREFIXED_GROUPS = ("limits",)

#: Options handled elsewhere than by a generated flag (``--mcap FILE``, ``--live [HOST:]PORT``).
SKIPPED = ("mcap", "live")

#: The flags of earlier versions whose names the naming rule does not give, per section: the
#: option's path (``(group, key)``, or ``(link, protocol or ANY_KIND, key)``) -> the flag. A
#: path of one protocol whose option every protocol has (``("robot", "egm", "port")``) is a
#: flag of its own beside the link's (``--egm-port`` beside ``--robot-port``).
HISTORICAL_NAMES: dict[str, dict[tuple[str, ...], str]] = {
    "runtime": {
        ("sensor", ANY_KIND, "host"): "--sensor",
        ("sensor", "rdt", "http_port"): "--http-port",
        ("sensor", "rdt", "counts_per_force"): "--counts-per-force",
        ("sensor", "rdt", "counts_per_torque"): "--counts-per-torque",
        ("sensor", "rdt", "bias"): "--bias",
        ("robot", ANY_KIND, "robot_host"): "--robot",
        ("robot", "egm", "port"): "--egm-port",
        ("robot", "egm", "bind_host"): "--egm-bind",
        ("robot", "egm", "offset_mm"): "--egm-offset",
        ("robot", "egm", "rotation"): "--egm-rotation",
        ("offset", "mode"): "--offset",
        ("offset", "max_force"): "--max-offset-force",
        ("offset", "max_moment"): "--max-offset-moment",
        ("scheduling", "priority"): "--rt-priority",
        ("scheduling", "lock_memory"): "--no-lock-memory",
        ("scheduling", "cpu"): "--cpu",
    },
    "facility": {
        ("sensor", ANY_KIND, "bind_host"): "--bind-host",
        ("sensor", "rdt", "http_port"): "--http-port",
        ("sensor", "rdt", "counts_per_force"): "--counts-per-force",
        ("sensor", "rdt", "counts_per_torque"): "--counts-per-torque",
        ("robot", "egm", "host"): "--egm-host",
        ("robot", "egm", "port"): "--egm-port",
        ("robot", "egm", "local_port"): "--egm-local-port",
        ("robot", "egm", "offset_mm"): "--egm-offset",
        ("robot", "egm", "rotation"): "--egm-rotation",
    },
}

_METAVARS = {3: "X,Y,Z", 4: "W,X,Y,Z"}


@dataclass(frozen=True)
class RealtimeFlag:
    """One generated flag: its name (``--force-limit``), the click parameter's name
    (``dest``), the option's path (``("limits", "force_limit")``, ``("connect_timeout",)``,
    ``("sensor", "rdt", "http_port")`` with ``ANY_KIND`` for every protocol of the link), the
    flat key of earlier versions it sets instead (or None), the number of values of a list
    option (0: not a list), the values of a choice (text -> value), and the click option."""

    name: str
    dest: str
    path: tuple[str, ...]
    legacy: str | None
    length: int
    choices: Mapping[str, Any] | None
    option: Any

    def value(self, given: Any) -> Any:
        """The option's value from what click parsed (None: not given)."""
        if given is None or given is False:  # False: an on/off flag not given
            return None
        if self.length:
            return _numbers(given, self.length, self.name)
        if self.choices is not None:
            return self.choices[given]
        return given


@functools.cache
def _schema() -> dict[str, Any]:
    """The core's schema of the real-time options (``{}`` without the native core)."""
    try:
        return dict(json.loads(core().realtime_schema()))
    except HilContactError:  # native core not built: no generated flags
        return {}


def _resolve(node: Mapping[str, Any], defs: Mapping[str, Any]) -> dict[str, Any]:
    """``node`` with its ``$ref`` (to ``$defs``) merged in, the node's own keys first."""
    node = dict(node)
    while "$ref" in node:
        target = defs[node.pop("$ref").rsplit("/", 1)[-1]]
        node = {**target, **node}
    return node


def _types(node: Mapping[str, Any]) -> list[str]:
    kind = node.get("type", [])
    return [t for t in ([kind] if isinstance(kind, str) else kind) if t != "null"]


def _choices(node: Mapping[str, Any]) -> dict[str, Any] | None:
    """A choice's values by their text, from ``enum`` or a ``oneOf`` of ``const``; else None."""
    if "enum" in node:
        values = [v for v in node["enum"] if v is not None]
    elif "oneOf" in node and all("const" in v for v in node["oneOf"]):
        values = [v["const"] for v in node["oneOf"]]
    else:
        return None
    return {v if isinstance(v, str) else format(v, "g"): v for v in values}


def _help(description: str) -> str:
    """The description as one line, without its ``(CLI `--flag`)`` notes (the flag is here)."""
    text = " ".join(description.split())
    text = re.sub(r" ?\(CLI `[^)]*`\)", "", text)
    text = re.sub(r" ?\(CLI `[^`]*`; ([^)]*)\)", r" (\1)", text)
    return text


def _shown(value: Any) -> str:
    if isinstance(value, list):
        return ",".join(format(v, "g") for v in value)
    if isinstance(value, float):
        return format(value, "g")
    return str(value)


def _default_text(defaults: Mapping[str, Any]) -> str:
    """``[default: VALUE]``, or ``[default: the protocol's: RDT 49152, SRI 4008]`` when the
    protocols' defaults differ; empty without a default."""
    values = {kind: v for kind, v in defaults.items() if v is not None}
    if not values:
        return ""
    if len({json.dumps(v) for v in values.values()}) == 1 and len(values) == len(defaults):
        return f" [default: {_shown(next(iter(values.values())))}]"
    return " [default: the protocol's: " + ", ".join(f"{k.upper()} {_shown(v)}" for k, v in values.items()) + "]"


def _flag(section: str, path: tuple[str, ...], name: str, node: Mapping[str, Any],
          defaults: Mapping[str, Any]) -> RealtimeFlag | None:
    """The flag of one option (None for an option of another shape)."""
    dest = "opt_" + name.lstrip("-").replace("-", "_")
    legacy = next((key for key, where in LEGACY_KEYS.get(section, {}).items() if where == path), None)
    description = _help(str(node.get("description", "")))
    default = _default_text(defaults)
    types = _types(node)
    choices = _choices(node)
    length = 0
    kwargs: dict[str, Any] = {"default": None}
    if choices is not None:
        kwargs["type"] = click.Choice(list(choices))
    elif types == ["boolean"]:
        if any(defaults.values()):  # on by default: the flag turns it off
            name = name if name.startswith("--no-") else "--no-" + name[2:]
            description, default, choices = f"Turn off (on by default): {description}", "", {True: False}
        else:
            default, choices = "", {True: True}
        kwargs = {"is_flag": True, "default": None}
    elif types == ["number"]:  # a finite number up to the maximum; the lower bound in the Rust parse
        kwargs["type"] = _Number(max=node.get("maximum"))
    elif types == ["integer"]:
        low = node.get("minimum")
        if "exclusiveMinimum" in node:
            low = int(node["exclusiveMinimum"]) + 1
        kwargs["type"] = click.IntRange(low, node.get("maximum"))
    elif types == ["string"]:
        kwargs["metavar"] = "HOST" if path[-1].endswith("host") else "TEXT"
    elif types == ["array"] and _types(node.get("items", {})) == ["number"] and node.get("minItems") == node.get("maxItems"):
        length = int(node["minItems"])
        kwargs["metavar"] = _METAVARS.get(length, f"N1,...,N{length}")
    else:
        return None
    option = click.option(name, dest, help=description + default, **kwargs)
    return RealtimeFlag(name, dest, path, legacy, length, choices, option)


def flags_from_schema(section: str, schema: Mapping[str, Any] | None = None,
                      only: Sequence[str] | None = None) -> list[RealtimeFlag]:
    """The flags of a section's options (``runtime`` or ``facility``), in the schema's order:
    the links' (``sensor``, ``robot``), then the others; ``only``: just these top-level
    options or groups. ``schema``: ``{"runtime": ..., "facility": ...}`` (default: the core's)."""
    schema = _schema() if schema is None else schema
    root = schema.get(section)
    if not root:
        return []
    defs = root.get("$defs", {})
    names = HISTORICAL_NAMES.get(section, {})
    flags: list[RealtimeFlag] = []

    def add(path: tuple[str, ...], rule: str, node: Mapping[str, Any], defaults: Mapping[str, Any]) -> None:
        flag = _flag(section, path, names.get(path, rule), node, defaults)
        if flag is not None:
            flags.append(flag)

    for key, raw in root.get("properties", {}).items():
        if key in SKIPPED or (only is not None and key not in only):
            continue
        node = _resolve(raw, defs)
        if key in LINKS and "oneOf" in node:
            variants = {}
            for variant in node["oneOf"]:
                variant = _resolve(variant, defs)
                kind = variant["properties"]["kind"]["const"]
                variants[kind] = {k: _resolve(v, defs) for k, v in variant["properties"].items() if k != "kind"}
            every = [k for k in next(iter(variants.values())) if all(k in v for v in variants.values())]
            for field in every:
                first = next(v[field] for v in variants.values())
                add((key, ANY_KIND, field), f"--{key}-{field.replace('_', '-')}", first,
                    {kind: v[field].get("default") for kind, v in variants.items()})
            for kind, fields in variants.items():
                for field, field_node in fields.items():
                    path = (key, kind, field)
                    if field not in every or path in names:
                        add(path, f"--{kind}-{field.replace('_', '-')}", field_node, {kind: field_node.get("default")})
        elif "properties" in node:
            for field, field_raw in node["properties"].items():
                field_node = _resolve(field_raw, defs)
                rule = field if key in UNPREFIXED_GROUPS else f"{key}_{field}"
                add((key, field), "--" + rule.replace("_", "-"), field_node, {"": field_node.get("default")})
        else:
            add((key,), "--" + key.replace("_", "-"), node, {"": node.get("default")})
    return flags


def options_from_flags(section: str, flags: Sequence[RealtimeFlag], given: dict[str, Any],
                       options: dict[str, Any] | None = None) -> dict[str, Any]:
    """The options from the generated flags' values (``given``: click's parameters; those of
    the flags are taken out of it), added to ``options`` (the links' groups from
    ``--sensor-protocol``/``--sensor-option``...): a top-level option by its key, a group's in
    its group, a link's in its group (a protocol's option implying its ``kind``, refused with
    another), or under its flat key of earlier versions when there is one."""
    options = dict(options or {})
    for flag in flags:
        value = flag.value(given.pop(flag.dest, None))
        if value is None:
            continue
        if flag.legacy is not None:
            options[flag.legacy] = value
        elif len(flag.path) == 3:
            link, kind, key = flag.path
            group = options.get(link) or {}
            if kind != ANY_KIND:
                chosen = group.setdefault("kind", kind)
                if chosen != kind:
                    raise RealtimeOptionError(f"{section} option {flag.name} belongs to {link} kind {kind!r}, not {chosen!r}")
            options[link] = {**group, key: value}
        elif len(flag.path) == 2:
            options[flag.path[0]] = {**(options.get(flag.path[0]) or {}), flag.path[1]: value}
        else:
            options[flag.path[0]] = value
    return options
