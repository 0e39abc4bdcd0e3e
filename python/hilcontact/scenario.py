"""Scenario files: schema, validation, presets and overrides.

A scenario is a TOML file (see ``scenarios/paper-table1.toml`` for the canonical format).
Conventions (the same as the core's, see the spec ``hil-loop.md`` section 2):

- SI units everywhere: m, s, N, N m, kg, rad.
- Frames: the target mockup frame ``t`` (fixed on the ground; wall points and normals, the
  sensor pose) and body frames at each satellite's centre of mass (rod tip, angular
  velocities). Quaternions are ``[w, x, y, z]``.
- A wall is a point and a unit normal pointing from the wall into free space.

The schema is the core's (``_core.scenario_schema()``, from ``crates/core/src/config.rs`` and
the compensators' parameters): the pydantic models here (:class:`Scenario`, ``Body``,
``Facility``, one per compensator kind in :data:`COMPENSATOR_MODELS`, ...) are built from it
at import, with its names, defaults, descriptions (units), allowed values and ranges. Nothing
of the schema is written again in Python.

Validation is done in two steps, and every problem is reported as a
:class:`~hilcontact.errors.ScenarioError` with a single line that names the key as a dotted
path (``servicer.mass``, ``walls[0].normal``) and says what is allowed; its ``issues`` lists
every problem as ``(key, message)``. First pydantic (``extra="forbid"``, strict types) checks
the file's shape, types and ranges, with messages that name unknown keys and suggest close
ones; then the core resolves the scenario (``_core.resolve_scenario``) and reports its other
problems (non-zero normals and quaternions, positive-definite inertia, whole-period delays,
duplicate wall names, ...). The validated :class:`Scenario` is the core's *resolved*
scenario: defaults filled in, inertia as a 3x3 matrix, quaternions and wall normals
normalised, wall names set and (with ``facility.round_delays``) delays rounded to whole
periods. ``Scenario.to_toml()`` writes that resolved form, and loading it again gives an
identical scenario.
"""

from __future__ import annotations

import copy
import difflib
import json
import math
import os
import re
import stat
import sys
import tomllib
import typing
from collections.abc import Mapping
from importlib import resources
from typing import Annotated, Any, Literal, Union

import tomli_w
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    PrivateAttr,
    Tag,
    ValidationError,
    create_model,
)

from . import _core
from .errors import ArgumentError, ScenarioError, describe
from .native import VERSION
from .registry import KINDS

# the table and compensator models (Simulation, Body, ..., PicCompensator, ...) are added below,
# as they are built from the core's schema
__all__ = [
    "COMPENSATOR_MODELS",
    "SCHEMA",
    "Scenario",
    "apply_overrides",
    "load_scenario",
    "preset_names",
    "presets",
]

# --------------------------------------------------------------------------------------
# Value helpers (they raise ValueError; pydantic attaches the key, _format_error words it)
# --------------------------------------------------------------------------------------


def _show(value: Any, limit: int = 60) -> str:
    """A short, TOML-like rendering of a user value for error messages."""
    if isinstance(value, str):
        text = repr(value)
    elif isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, (list, tuple)):
        text = "[" + ", ".join(_show(v, limit) for v in value) + "]"
    elif isinstance(value, Mapping):
        text = "a table {" + ", ".join(str(k) for k in value) + "}"
    else:
        text = describe(value, limit)  # never fails (an integer above Python's digit limit)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _fmt(value: float) -> str:
    """A float as a short decimal, for messages and rounded values (an int as it is)."""
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    return f"{value:.12g}"


def _plain(value: Any) -> Any:
    """numpy scalars/arrays and tuples to plain Python values (for overrides and vectors)."""
    if hasattr(value, "tolist") and callable(value.tolist) and type(value).__module__.startswith("numpy"):
        return value.tolist()
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    return value


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _numbers(value: Any, n: int, what: str) -> list[float]:
    value = _plain(value)
    if not isinstance(value, list) or len(value) != n or not all(_is_number(v) for v in value):
        raise ValueError(f"expected {what}, got {_show(value)}")
    out = [float(v) for v in value]
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"expected finite numbers, got {_show(value)}")
    return out


def _vec3(value: Any) -> list[float]:
    return _numbers(value, 3, "3 numbers [x, y, z]")


def _quaternion(value: Any) -> list[float]:
    return _numbers(value, 4, "a quaternion [w, x, y, z] (4 numbers)")


_INERTIA_ALLOWED = (
    "3 principal moments [Ixx, Iyy, Izz] > 0 or a 3x3 symmetric positive-definite matrix (kg m^2)"
)


def _inertia(value: Any) -> list[float] | list[list[float]]:
    """The shape of an inertia (its values are checked by the core)."""
    value = _plain(value)
    if isinstance(value, list) and len(value) == 3 and all(_is_number(v) for v in value):
        return _vec3(value)
    if isinstance(value, list) and len(value) == 3 and all(isinstance(r, list) for r in value):
        try:
            return [_vec3(row) for row in value]
        except ValueError:
            raise ValueError(f"expected {_INERTIA_ALLOWED}, got {_show(value)}") from None
    raise ValueError(f"expected {_INERTIA_ALLOWED}, got {_show(value)}")


# The values of the schema's `x-value` marker: the shape check of each (the core checks the
# rest: non-zero normals and quaternions, symmetric positive-definite inertia).
_VALUE_CHECKS: dict[str, Any] = {"vec3": _vec3, "quaternion": _quaternion, "inertia": _inertia}


def _flat(value: Any) -> list[float]:
    return [x for item in value for x in _flat(item)] if isinstance(value, list) else [value]


def _value_type(marker: str, magnitude: float | None) -> Any:
    """The annotation of an `x-value` field: its shape check, and with the schema's
    `x-magnitude` the largest ``|x|`` of each of its numbers."""
    shape = _VALUE_CHECKS[marker]

    def check(value: Any) -> Any:
        checked = shape(value)
        if magnitude is not None and not all(abs(x) <= magnitude for x in _flat(checked)):
            raise ValueError(f"every number must be finite with |x| <= {_bound(magnitude)}, got {_show(value)}")
        return checked

    return Annotated[Any if marker == "inertia" else list[float], BeforeValidator(check)]


def _nonzero_minimum(smallest: float) -> Any:
    """The check of the schema's `x-nonzero-minimum`: 0 (none) or at least ``smallest``."""

    def check(value: float) -> float:
        if value != 0 and abs(value) < smallest:
            raise ValueError(f"must be 0 (none) or >= {_bound(smallest)}, got {_show(value)}")
        return value

    return check


#: The largest value of the schema's unsigned integer formats (the core's u32, u64).
_UINT_MAX = {"uint32": 2**32 - 1, "uint64": 2**64 - 1}


# --------------------------------------------------------------------------------------
# Schema: built from the core's (`_core.scenario_schema()`), nothing written again here
# --------------------------------------------------------------------------------------


class _Table(BaseModel):
    """Base of every table: unknown keys are errors, no silent type coercion."""

    model_config = ConfigDict(extra="forbid", strict=True)


SCHEMA: dict[str, Any] = json.loads(_core.scenario_schema())
"""The core's JSON Schema of a scenario file (names, defaults, units, allowed values, ranges)."""

_DEFS: dict[str, Any] = SCHEMA.get("$defs", {})


def _deref(prop: Mapping[str, Any]) -> tuple[str | None, dict[str, Any]]:
    """A property's schema with its `$ref` merged in (the property's own keys win)."""
    ref = prop.get("$ref")
    if not ref:
        return None, dict(prop)
    name = ref.rsplit("/", 1)[-1]
    return name, {**_DEFS[name], **{k: v for k, v in prop.items() if k != "$ref"}}


def _description(schema: Mapping[str, Any]) -> str | None:
    text = schema.get("description")
    return " ".join(text.split()) if text else None


def _choices(schema: Mapping[str, Any]) -> list[str] | None:
    """The allowed strings of an enum (`enum`, or `oneOf` of `const`s)."""
    if "enum" in schema:
        return list(schema["enum"])
    variants = schema.get("oneOf")
    if variants and all("const" in v and v.get("type") == "string" for v in variants):
        return [v["const"] for v in variants]
    return None


def _is_tagged_union(schema: Mapping[str, Any]) -> bool:
    variants = schema.get("oneOf") or []
    return bool(variants) and all("const" in v.get("properties", {}).get("kind", {}) for v in variants)


def _camel(text: str) -> str:
    return "".join(part[:1].upper() + part[1:] for part in re.split(r"[-_]", text))


def _field(prop: Mapping[str, Any], required: bool) -> tuple[Any, Any]:
    """The annotation and Field of one property of the core's schema."""
    ref, schema = _deref(prop)
    kwargs: dict[str, Any] = {"description": _description(schema)}
    marker = schema.get("x-value")
    choices = _choices(schema)
    factory: Any = None
    if marker is not None:
        annotation = _value_type(marker, schema.get("x-magnitude"))
    elif choices is not None:
        annotation = Literal[tuple(choices)]  # type: ignore[valid-type]
    elif _is_tagged_union(schema):
        annotation = Compensator
        if "default" in schema:
            factory = lambda d=schema["default"]: _compensator_model(d).model_validate(copy.deepcopy(d))  # noqa: E731
    elif schema.get("type") == "object" and ref is not None:
        annotation = _table_model(ref)
        if "default" in schema:
            factory = lambda m=annotation, d=schema["default"]: m.model_validate(copy.deepcopy(d))  # noqa: E731
    elif schema.get("type") == "array":
        _, item = _deref(schema["items"])
        item_ref = schema["items"].get("$ref")
        annotation = list[_table_model(item_ref.rsplit("/", 1)[-1])] if item_ref else list[Any]  # type: ignore[misc]
        if "minItems" in schema:
            kwargs["min_length"] = schema["minItems"]
    elif schema.get("type") in ("number", "integer"):
        annotation = float if schema["type"] == "number" else int
        if annotation is float:
            kwargs["allow_inf_nan"] = False
        for key, name in (("minimum", "ge"), ("exclusiveMinimum", "gt"), ("maximum", "le"), ("exclusiveMaximum", "lt")):
            if key in schema:
                kwargs[name] = schema[key]
        if annotation is int and "maximum" not in schema and schema.get("format") in _UINT_MAX:
            kwargs["le"] = _UINT_MAX[schema["format"]]
        if "x-nonzero-minimum" in schema:
            annotation = Annotated[annotation, AfterValidator(_nonzero_minimum(schema["x-nonzero-minimum"]))]
    elif schema.get("type") == "boolean":
        annotation = bool
    elif schema.get("type") == "string":
        annotation = str
        if "minLength" in schema:
            kwargs["min_length"] = schema["minLength"]
        if "maxLength" in schema:
            kwargs["max_length"] = schema["maxLength"]
    else:  # pragma: no cover - a schema shape this module does not know
        raise ImportError(f"hilcontact.scenario cannot read the core's schema {schema!r}")
    if factory is not None:
        return annotation, Field(default_factory=factory, **kwargs)
    if "default" in schema:
        default = schema["default"]
        if isinstance(default, (list, dict)):
            return annotation, Field(default_factory=lambda d=default: copy.deepcopy(d), **kwargs)
        return annotation, Field(default, **kwargs)
    if not required:  # pragma: no cover - the core gives every optional key a default
        raise ImportError(f"the core's schema gives no default for {prop!r}")
    return annotation, Field(**kwargs)


def _fields(schema: Mapping[str, Any]) -> dict[str, tuple[Any, Any]]:
    required = set(schema.get("required", ()))
    return {name: _field(prop, name in required) for name, prop in schema.get("properties", {}).items()}


_TABLE_MODELS: dict[str, type[_Table]] = {}


def _table_model(def_name: str) -> type[_Table]:
    """The model of a table of the core's schema (`BodyConfig` -> `Body`)."""
    if def_name not in _TABLE_MODELS:
        schema = _DEFS[def_name]
        name = def_name.removesuffix("Config")
        model = create_model(name, __base__=_Table, __module__=__name__, **_fields(schema))  # type: ignore[call-overload]
        model.__doc__ = _description(schema)
        _TABLE_MODELS[def_name] = model
    return _TABLE_MODELS[def_name]


def _compensator_models() -> dict[str, type[_Table]]:
    """One model per compensator kind, from the core's tagged union, in the registry's order."""
    union = next(_deref(p)[1] for p in SCHEMA["properties"].values() if _is_tagged_union(_deref(p)[1]))
    models: dict[str, type[_Table]] = {}
    for variant in union["oneOf"]:
        kind = variant["properties"]["kind"]["const"]
        fields: dict[str, Any] = {"kind": (Literal[kind], Field(kind, description="the compensator kind"))}
        fields.update({k: v for k, v in _fields(variant).items() if k != "kind"})
        model = create_model(  # type: ignore[call-overload]
            f"{_camel(kind)}Compensator", __base__=_Table, __module__=__name__, **fields
        )
        model.__doc__ = f"``kind = {kind!r}``: {_description(variant) or ''}"
        models[kind] = model
    return models


COMPENSATOR_MODELS: dict[str, type[_Table]] = _compensator_models()
"""The schema of each compensator kind's table, in the core registry's order."""

if list(COMPENSATOR_MODELS) != list(KINDS):  # pragma: no cover - the core contradicts itself
    raise ImportError(f"the core's schema lists kinds {list(COMPENSATOR_MODELS)}, its registry {list(KINDS)}")


def _compensator_model(value: Any) -> type[_Table]:
    return COMPENSATOR_MODELS[_compensator_kind(value)]


def _compensator_kind(value: Any) -> Any:
    if isinstance(value, Mapping):
        return value.get("kind", "none")
    return getattr(value, "kind", None)


Compensator = Annotated[
    Union[tuple(Annotated[cls, Tag(kind)] for kind, cls in COMPENSATOR_MODELS.items())],  # type: ignore[misc]
    Discriminator(
        _compensator_kind,
        custom_error_type="compensator_kind",
        custom_error_message="unknown compensator kind",
    ),
]


def _issue_line(key: str, message: str) -> str:
    """One problem found by the core as a line: ``key: message``, or ``key = value s ...``
    when the message starts with the key's value (``facility.robot_delay = 0.0125 s is not a
    whole number of periods ...``)."""
    if re.match(r"^-?[0-9][0-9.e+-]* s ", message):
        return f"{key} = {message}"
    return f"{key}: {message}"


def _summary(lines: list[str]) -> str:
    """The first line, and the keys of the others: ``... (and 2 more: target.mass, x)``."""
    message = lines[0]
    if len(lines) > 1:
        others = [line.split(":", 1)[0].split(" = ", 1)[0] for line in lines[1:]]
        message += f" (and {len(lines) - 1} more: {', '.join(others)})"
    return message


PYTHON_KIND = "python"
"""``compensator.kind`` of a compensator written in Python, named by ``compensator.entry``
(``"path/file.py:Class"`` or ``"module:Class"``, see :mod:`hilcontact.plugin`); the core
runs such a scenario with ``kind = "none"`` in place and the Python compensator stepping."""


def _split_python_compensator(data: Mapping[str, Any]) -> tuple[Mapping[str, Any], str | None]:
    """A raw scenario with ``compensator.kind = "python"``: the data with ``kind = "none"`` in
    its place, and the entry (None for any other kind)."""
    table = data.get("compensator") if isinstance(data, Mapping) else None
    if not isinstance(table, Mapping) or table.get("kind") != PYTHON_KIND:
        return data, None
    for key in table:
        if key not in ("kind", "entry"):
            raise ScenarioError(f"compensator.{key}: unknown key for kind = 'python'; allowed: entry")
    entry = table.get("entry")
    if not isinstance(entry, str) or ":" not in entry.strip(":"):
        raise ScenarioError(
            f"compensator.entry: expected path/to/file.py:ClassName or module:ClassName, got {_show(entry)}"
        )
    return {**data, "compensator": {"kind": "none"}}, entry


class _ScenarioBase(_Table):
    """A fully resolved scenario. Build it with :func:`load_scenario` or :meth:`from_dict`."""

    _python_entry: str | None = PrivateAttr(default=None)

    @property
    def python_entry(self) -> str | None:
        """``compensator.entry`` when ``compensator.kind = "python"`` (then ``compensator`` here
        is ``none``, what the core runs in its place), else None."""
        return self._python_entry

    # ---- construction ------------------------------------------------------------------

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Scenario:
        """Validate a raw (TOML-shaped) dict and resolve it with the core; raise ScenarioError
        with a one-line message (every problem's key is named, ``issues`` lists them)."""
        data, entry = _split_python_compensator(data)
        try:
            checked = cls.model_validate(_plain(data))
        except ValidationError as exc:
            raise _scenario_error(exc) from None
        except RecursionError:
            raise ScenarioError("scenario: a value is nested too deeply (a scenario's values are numbers, strings, lists of numbers and tables)") from None
        try:
            resolved = _core.resolve_scenario(checked.to_json())
        except ScenarioError as exc:
            issues = list(getattr(exc, "issues", None) or [])
            if not issues:
                raise
            error = ScenarioError(_summary([_issue_line(key, message) for key, message in issues]))
            error.issues = issues
            raise error from None
        scenario = cls.model_validate(json.loads(resolved))
        scenario._python_entry = entry
        return scenario

    @classmethod
    def from_toml(cls, text: str, source: str = "<string>") -> Scenario:
        """Parse and validate TOML text."""
        return cls.from_dict(_parse_toml(text, source))

    # ---- output ------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """The resolved scenario as plain data (the schema of the TOML file and of the JSON)."""
        data = self.model_dump(mode="json")
        if self._python_entry is not None:
            data["compensator"] = {"kind": PYTHON_KIND, "entry": self._python_entry}
        return data

    def to_json(self) -> str:
        """The resolved scenario as JSON, the input of ``hilcontact._core.simulate`` (a Python
        compensator's scenario with ``kind = "none"`` in its place)."""
        return json.dumps(self.model_dump(mode="json"))

    def to_toml(self) -> str:
        """The fully resolved scenario as TOML; loading it again gives an identical Scenario."""
        header = (
            f"# Resolved scenario {self.name!r}, written by hilcontact {VERSION}.\n"
            "# Every value is explicit (defaults filled in); SI units, frames as in the docs.\n"
        )
        return header + _compact_arrays(tomli_w.dumps(self.to_dict()))


Scenario = create_model(  # type: ignore[call-overload]
    "Scenario", __base__=_ScenarioBase, __module__=__name__, **_fields(SCHEMA)
)
Scenario.__doc__ = _ScenarioBase.__doc__

_TABLES: dict[str, Any] = {}
"""Each top-level table's model (the compensator's: the models by kind)."""
for _name, _prop in SCHEMA["properties"].items():
    _ref, _schema = _deref(_prop)
    if _is_tagged_union(_schema):
        _TABLES[_name] = COMPENSATOR_MODELS
    elif _schema.get("type") == "object" and _ref is not None:
        _TABLES[_name] = _table_model(_ref)
    elif _schema.get("type") == "array" and "$ref" in _schema.get("items", {}):
        _TABLES[_name] = _table_model(_schema["items"]["$ref"].rsplit("/", 1)[-1])

# the public names of the tables (Simulation, Body, ...) and compensators (PicCompensator, ...)
for _model in [*_TABLE_MODELS.values(), *COMPENSATOR_MODELS.values()]:
    globals()[_model.__name__] = _model
    if _model.__name__ not in __all__:
        __all__.append(_model.__name__)
__all__.sort()


_MULTILINE_ARRAY = re.compile(r"\[\n((?:[ \t]*[^\[\]\n]*,\n)+)[ \t]*\]")


def _compact_arrays(text: str, width: int = 100) -> str:
    """Put tomli_w's one-item-per-line arrays on one line (innermost first), for readability.

    The result is checked to parse to the same data; if not, the original text is kept.
    """

    def join(match: re.Match[str]) -> str:
        items = [line.strip().rstrip(",") for line in match.group(1).splitlines()]
        joined = "[" + ", ".join(items) + "]"
        return joined if len(joined) <= width else match.group(0)

    compact = text
    while True:
        candidate = _MULTILINE_ARRAY.sub(join, compact)
        if candidate == compact:
            break
        compact = candidate
    if tomllib.loads(compact) != tomllib.loads(text):
        return text
    return compact


# --------------------------------------------------------------------------------------
# Error messages
# --------------------------------------------------------------------------------------


def _locate(loc: tuple[Any, ...]) -> tuple[list[str | int], Any]:
    """Turn a pydantic error location into key parts, and find the model owning the last key.

    Drops the tag that pydantic inserts for the tagged compensator union.
    """
    parts: list[str | int] = []
    owner: Any = None
    current: Any = Scenario
    for part in loc:
        if isinstance(part, int):
            parts.append(part)
            continue
        if isinstance(current, dict):  # tagged union: the next element is the tag
            if part in current:
                current = current[part]
                continue
            current = None
        owner = current
        parts.append(part)
        if current is Scenario:
            current = _TABLES.get(part)
        else:  # a table inside a table (e.g. [contact.friction]): its model, if it is one
            field = getattr(current, "model_fields", {}).get(part) if isinstance(current, type) else None
            sub = getattr(field, "annotation", None)
            if typing.get_origin(sub) is list:  # a list of tables (e.g. [[servicer.shapes]])
                sub = typing.get_args(sub)[0]
            current = sub if isinstance(sub, type) and issubclass(sub, _Table) else None
    return parts, owner


def _dotted(parts: list[str | int]) -> str:
    out = ""
    for part in parts:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + part
    return out


def _table_label(parts: list[str | int], owner: Any) -> str:
    if not parts:
        return "the top level"
    if parts[0] == "walls":
        return "[[walls]]"
    if parts[0] == "compensator" and owner is not None and "kind" in getattr(owner, "model_fields", {}):
        return f"[compensator] with kind = {owner.model_fields['kind'].default!r}"
    return f"[{_dotted(parts)}]"


def _error_line(err: Mapping[str, Any]) -> str:
    parts, owner = _locate(tuple(err.get("loc", ())))
    path = _dotted(parts)
    kind = err["type"]
    value = err.get("input")
    ctx = err.get("ctx") or {}
    key = parts[-1] if parts else None
    field = getattr(owner, "model_fields", {}).get(key) if isinstance(key, str) and owner is not None else None

    def at(message: str) -> str:
        return f"{path}: {message}" if path else message

    if kind == "missing":
        if owner is Scenario and key in _TABLES:
            if key == "walls":
                return "walls: missing; at least one [[walls]] table is required"
            return f"{key}: missing required table [{key}]"
        hint = f" ({_hint(field.description)})" if field is not None and field.description else ""
        return at(f"missing required value{hint}")
    if kind == "extra_forbidden":
        allowed = list(getattr(owner, "model_fields", {}))
        close = difflib.get_close_matches(str(key), allowed, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        where = _table_label(parts[:-1], owner)
        if not parts[:-1]:
            return f"{key}: unknown top-level key{hint}; allowed: {', '.join(allowed)}"
        message = f"unknown key{hint}; allowed keys in {where}: {', '.join(allowed)}"
        if parts[:-1] == ["compensator"]:
            kinds = [k for k, cls in COMPENSATOR_MODELS.items() if key in cls.model_fields]
            if kinds:
                message += f" ({key!r} is a parameter of kind {', '.join(repr(k) for k in kinds)})"
        return at(message)
    if kind == "compensator_kind":
        if isinstance(value, Mapping):
            allowed = ", ".join(repr(k) for k in COMPENSATOR_MODELS)
            return f"{path}.kind: unknown compensator kind {_show(value.get('kind'))}; allowed: {allowed}"
        return at(f"expected a table, got {_show(value)}")
    if kind in ("float_type", "float_parsing"):
        return at(f"expected a number, got {_show(value)}")
    if kind in ("int_type", "int_parsing", "int_from_float"):
        return at(f"expected an integer, got {_show(value)}")
    if kind in ("bool_type", "bool_parsing"):
        return at(f"expected true or false, got {_show(value)}")
    if kind in ("string_type", "string_sub_type"):
        return at(f"expected a string, got {_show(value)}")
    if kind == "string_too_long":
        return at(f"must be at most {ctx.get('max_length')} characters, got {len(value)}: {_show(value)}")
    if kind == "string_too_short":
        return at(f"must be at least {ctx.get('min_length')} character(s), got {_show(value)}")
    if kind == "finite_number":
        return at(f"must be a finite number, got {_show(value)}")
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        return at(f"must be {_range_words(field)}, got {_show(value)}")
    if kind == "literal_error":
        return at(f"must be one of {ctx.get('expected')}, got {_show(value)}")
    if kind in ("model_type", "dict_type", "model_attributes_type"):
        what = "a [[walls]] table" if parts and parts[0] == "walls" else "a table"
        return at(f"expected {what}, got {_show(value)}")
    if kind == "list_type":
        if parts == ["walls"]:
            return at(f"expected one or more [[walls]] tables, got {_show(value)}")
        return at(f"expected a list, got {_show(value)}")
    if kind == "too_short" and parts == ["walls"]:
        return "walls: at least one [[walls]] table is required"
    if kind in ("value_error", "assertion_error"):
        message = str(ctx.get("error", err.get("msg", "")))
        return at(message)
    return at(str(err.get("msg", kind)))


def _hint(description: str) -> str:
    """A field's description as a hint: its first sentence, without the final period
    (``Control period T in s, > 0.`` -> ``control period T in s, > 0``)."""
    first = re.split(r"(?<=\.)\s", description, maxsplit=1)[0].rstrip(".")
    if len(first) > 1 and first[0].isupper() and first[1].islower():
        first = first[0].lower() + first[1:]
    return first


def _bound(value: float) -> str:
    """A range's bound, short: ``0``, ``0.001``, ``86400``, ``1e-6``, ``1e11``."""
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    if value == 0 or 1e-3 <= abs(value) < 1e6:
        return _fmt(value)
    mantissa, exponent = f"{value:.11e}".split("e")
    return f"{mantissa.rstrip('0').rstrip('.')}e{int(exponent)}"


def _range_words(field: Any) -> str:
    """The range of a field in the core's words: ``> 0``, ``>= 1``, ``between 0 and 1
    (exclusive)``."""
    bounds: dict[str, Any] = {}
    for item in getattr(field, "metadata", ()):
        for name in ("ge", "gt", "le", "lt"):
            if getattr(item, name, None) is not None:
                bounds[name] = getattr(item, name)
    if "gt" in bounds and "lt" in bounds and len(bounds) == 2:
        return f"between {_bound(bounds['gt'])} and {_bound(bounds['lt'])} (exclusive)"
    if "ge" in bounds and "le" in bounds and len(bounds) == 2:
        return f"between {_bound(bounds['ge'])} and {_bound(bounds['le'])}"
    ops = {"ge": ">=", "gt": ">", "le": "<=", "lt": "<"}
    return " and ".join(f"{ops[name]} {_bound(bound)}" for name, bound in bounds.items())


def _scenario_error(exc: ValidationError) -> ScenarioError:
    """One ScenarioError for every problem pydantic found (one line, ``issues`` lists them)."""
    lines: list[str] = []
    for err in exc.errors(include_url=False):
        line = _error_line(err)
        if line not in lines:
            lines.append(line)
    if not lines:  # pragma: no cover - pydantic always reports something
        lines = ["invalid scenario"]
    error = ScenarioError(_summary(lines))
    error.issues = [tuple(line.split(": ", 1)) if ": " in line else ("", line) for line in lines]
    return error


# --------------------------------------------------------------------------------------
# Loading: presets, files, overrides
# --------------------------------------------------------------------------------------


def _preset_files() -> dict[str, Any]:
    folder = resources.files("hilcontact").joinpath("scenarios")
    return {
        entry.name[: -len(".toml")]: entry
        for entry in folder.iterdir()
        if entry.name.endswith(".toml") and entry.is_file()
    }


def preset_names() -> list[str]:
    """Names of the embedded presets, sorted."""
    return sorted(_preset_files())


def presets() -> dict[str, str]:
    """The embedded presets: name -> description."""
    out: dict[str, str] = {}
    files = _preset_files()
    for name in sorted(files):
        raw = _parse_toml(files[name].read_text(encoding="utf-8"), f"preset {name!r}")
        out[name] = str(raw.get("description", ""))
    return out


def _parse_toml(text: str, source: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: invalid TOML: {exc}") from None
    except RecursionError:
        raise ScenarioError(f"{source}: invalid TOML: arrays or tables nested too deeply") from None
    except ValueError:  # an integer above Python's limit on digits (sys.get_int_max_str_digits)
        key = _long_number_key(text) or "a value"
        raise ScenarioError(
            f"{source}: {key}: a number of more than {sys.get_int_max_str_digits()} digits; "
            "give a number such as 0.02 or 1e30"
        ) from None


_TABLE_HEADER = re.compile(r"^\s*\[+\s*([^\]]+?)\s*\]+")
_KEY_VALUE = re.compile(r"^\s*([A-Za-z0-9_.\-\"' ]+?)\s*=\s*(.*)$")


def _long_number_key(text: str) -> str | None:
    """The dotted key of the first value of ``text`` (TOML) with a run of more digits than
    Python converts (best effort, for the message), None if none is found."""
    limit = sys.get_int_max_str_digits() or 4300
    digits = re.compile(r"[0-9_]{%d,}" % (limit + 1))
    table = ""
    for line in text.splitlines():
        header = _TABLE_HEADER.match(line)
        if header and "=" not in line.split("]")[0]:
            table = header.group(1).replace('"', "").replace("'", "")
            continue
        pair = _KEY_VALUE.match(line)
        if pair and digits.search(pair.group(2)):
            key = pair.group(1).strip().replace('"', "").replace("'", "")
            return f"{table}.{key}" if table else key
    return None


_SEGMENT = re.compile(r"^([A-Za-z_][A-Za-z0-9_-]*)((?:\[\d+\])*)$")


def _override_steps(key: Any) -> list[str | int]:
    """``"walls[0].point"`` -> ``["walls", 0, "point"]``."""
    if not isinstance(key, str) or not key:
        raise ScenarioError(f"invalid override key {key!r}: expected a dotted key such as facility.robot_delay")
    steps: list[str | int] = []
    for segment in key.split("."):
        match = _SEGMENT.match(segment.strip())
        if not match:
            raise ScenarioError(f"invalid override key {key!r}: expected a dotted key such as facility.robot_delay")
        steps.append(match.group(1))
        steps.extend(int(i) for i in re.findall(r"\[(\d+)\]", match.group(2)))
    return steps


def _switch_compensator_kind(data: dict[str, Any], kind: Any) -> None:
    """An override changes ``compensator.kind``: keep from the file only the parameters that
    the new kind has (the others belonged to the old kind). Parameters set by overrides are
    applied afterwards and validated as usual."""
    table = data.get("compensator")
    if kind == PYTHON_KIND and isinstance(table, dict) and table.get("kind") != PYTHON_KIND:
        data["compensator"] = {"kind": PYTHON_KIND}
        return
    if not isinstance(table, dict) or not isinstance(kind, str) or kind not in COMPENSATOR_MODELS:
        return  # not a table, or an unknown kind: validation reports it
    if table.get("kind", "none") == kind:
        return
    fields = COMPENSATOR_MODELS[kind].model_fields
    data["compensator"] = {name: value for name, value in table.items() if name in fields}


def apply_overrides(raw: Mapping[str, Any], overrides: Mapping[str, Any] | None) -> dict[str, Any]:
    """Return a copy of the raw scenario dict with dotted-key overrides applied.

    Keys are dotted paths into the TOML tables (``"facility.robot_delay"``); list items can
    be addressed as ``"walls[0].point"``. Missing tables are created; the result is validated
    later, so unknown keys are reported with the allowed ones.

    An override of ``compensator.kind`` to another kind keeps, of the file's ``[compensator]``
    parameters, only those that the new kind has (``--set compensator.kind=pida`` works on a
    file written for ``tdpa-impedance``). Compensator parameters set by overrides are always
    kept, so one that the new kind does not have is an error.
    """
    _check_overrides(overrides)
    data: dict[str, Any] = copy.deepcopy(dict(raw))
    parsed = [(key, _override_steps(key), value) for key, value in (overrides or {}).items()]
    for key, steps, value in parsed:
        if steps == ["compensator", "kind"]:
            _switch_compensator_kind(data, value)
    for key, steps, value in parsed:
        node: Any = data
        for depth, step in enumerate(steps[:-1]):
            here = _dotted(steps[: depth + 1])
            nxt = steps[depth + 1]
            if isinstance(step, int):
                if step >= len(node):
                    raise ScenarioError(f"{key}: {_dotted(steps[:depth])} has only {len(node)} item(s)")
                child = node[step]
            else:
                if step not in node:
                    node[step] = [] if isinstance(nxt, int) else {}
                child = node[step]
            if isinstance(nxt, int) and not isinstance(child, list):
                raise ScenarioError(f"{key}: {here} is not a list")
            if isinstance(nxt, str) and not isinstance(child, dict):
                raise ScenarioError(f"{key}: {here} is not a table, it is {_show(child)}")
            node = child
        last = steps[-1]
        if isinstance(last, int) and last >= len(node):
            raise ScenarioError(f"{key}: {_dotted(steps[:-1])} has only {len(node)} item(s)")
        try:
            node[last] = _plain(value)
        except RecursionError:
            raise ScenarioError(f"{key}: the value is nested too deeply") from None
    return data


def _check_overrides(overrides: Any) -> None:
    """Overrides are a mapping (or None); anything else is an :class:`ArgumentError`."""
    if overrides is not None and not isinstance(overrides, Mapping):
        raise ArgumentError(
            "overrides: expected a mapping of dotted keys to values, e.g. {'facility.robot_delay': 0.02}, "
            f"got {type(overrides).__name__} {_show(overrides)}"
        )


def _not_a_file(text: str) -> str | None:
    """Why the path ``text`` is not a TOML file to read (a directory, a device such as
    /dev/null, a FIFO, a socket, a symbolic link loop or one to a missing file), None for a
    regular file or a path that does not exist."""
    try:
        mode = os.stat(text).st_mode
    except OSError as exc:
        if exc.errno == getattr(os, "ELOOP", 40):
            return "a symbolic link loop"
        if os.path.islink(text):
            return f"a symbolic link to a missing file ({os.readlink(text)})"
        if exc.errno in (getattr(os, "ENOENT", 2), getattr(os, "ENOTDIR", 20)):
            return None
        return f"cannot be read: {exc.strerror or exc}"
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "is a directory"
    if stat.S_ISFIFO(mode):
        return "is a named pipe (FIFO)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "is a device"
    if stat.S_ISSOCK(mode):
        return "is a socket"
    return "is not a regular file"


def _read_source(source: Any) -> dict[str, Any]:
    if isinstance(source, Scenario):
        return source.to_dict()
    if isinstance(source, Mapping):
        return copy.deepcopy(dict(source))
    if not isinstance(source, (str, os.PathLike)):
        raise ArgumentError(f"scenario: expected a preset name, a TOML file path or a Scenario, got {_show(source)}")
    text = os.fspath(source)
    if not isinstance(text, str):
        raise ArgumentError(f"scenario: expected a preset name, a TOML file path or a Scenario, got {_show(source)}")
    files = _preset_files()
    if isinstance(source, str) and text in files:
        raw = _parse_toml(files[text].read_text(encoding="utf-8"), f"preset {text!r}")
        return _read_meshes(raw, os.fspath(files[text]))
    if "\x00" in text:
        raise ScenarioError(f"scenario {_show(text)}: a path cannot hold a NUL character")
    problem = _not_a_file(text)
    if problem is not None:
        raise ScenarioError(f"{text}: {problem}, expected a preset name or a TOML file")
    if os.path.isfile(text):
        try:
            with open(text, "rb") as handle:
                content = handle.read().decode("utf-8")
        except UnicodeDecodeError:
            raise ScenarioError(f"{text}: not a UTF-8 text file") from None
        except OSError as exc:
            raise ScenarioError(f"{text}: cannot read: {exc.strerror}") from None
        return _beside_file(_read_meshes(_parse_toml(content, text), text), text)
    names = ", ".join(sorted(files)) or "(none)"
    raise ScenarioError(f"unknown scenario {text!r}: not a preset and no such file; presets: {names}")


def _beside_file(raw: dict[str, Any], path: str) -> dict[str, Any]:
    """``facility.mujoco_model`` of a scenario file made relative to the file's folder (a path
    in a scenario file names a file beside it)."""
    facility = raw.get("facility")
    model = facility.get("mujoco_model") if isinstance(facility, dict) else None
    if isinstance(model, str) and model and not os.path.isabs(model):
        facility["mujoco_model"] = os.path.join(os.path.dirname(os.path.abspath(path)), model)
    return raw


def _read_meshes(raw: dict[str, Any], scenario_file: str | None) -> dict[str, Any]:
    """Fills the ``vertices`` and ``triangles`` of every mesh shape that names a ``file`` and
    has none yet, reading the file relative to ``scenario_file``'s folder (the working folder
    without one). A missing or malformed file: one line naming the key and the file."""
    base = os.path.dirname(os.path.abspath(scenario_file)) if scenario_file else os.getcwd()
    for body in ("servicer", "target"):
        table = raw.get(body)
        shapes = table.get("shapes") if isinstance(table, Mapping) else None
        if not isinstance(shapes, list):
            continue
        for i, shape in enumerate(shapes):
            if not isinstance(shape, dict) or shape.get("kind") != "mesh":
                continue
            name = shape.get("file")
            if not isinstance(name, str) or not name or shape.get("vertices"):
                continue
            path = os.path.join(base, name)
            try:
                vertices, triangles = _core.read_mesh(path)
            except (ValueError, OSError) as exc:
                raise ScenarioError(f"{body}.shapes[{i}].file: cannot read mesh {name!r} ({path}): {exc}") from None
            shape["vertices"] = vertices
            shape["triangles"] = triangles
    return raw


def load_scenario(source: Any, overrides: Mapping[str, Any] | None = None) -> Scenario:
    """Load and validate a scenario.

    ``source`` is a preset name (see :func:`presets`), a path to a TOML file, a raw dict or a
    :class:`Scenario`. ``overrides`` maps dotted keys (``"facility.robot_delay"``) to values and
    is applied to the raw TOML data before validation. Raises ScenarioError.
    """
    _check_overrides(overrides)
    raw = _read_source(source)
    if overrides:
        raw = apply_overrides(raw, overrides)
    return Scenario.from_dict(raw)
