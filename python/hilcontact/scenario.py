"""Scenario files: schema, validation, presets and overrides.

A scenario is a TOML file (see ``scenarios/paper-table1.toml`` for the canonical format).
Conventions (the same as the core's, see the spec ``hil-loop.md`` section 2):

- SI units everywhere: m, s, N, N m, kg, rad.
- Frames: the target mockup frame ``t`` (fixed on the ground; wall points and normals, the
  sensor pose) and body frames at each satellite's centre of mass (rod tip, angular
  velocities). Quaternions are ``[w, x, y, z]``.
- A wall is a point and a unit normal pointing from the wall into free space.

Validation is done with pydantic v2 (``extra="forbid"`` and strict types everywhere), and every
problem is reported as a :class:`~hilcontact.errors.ScenarioError` with a single line that
names the key as a dotted path (``servicer.mass``, ``walls[0].normal``) and says what is
allowed. The validated :class:`Scenario` is *resolved*: defaults filled in, inertia as a 3x3
matrix, quaternions and wall normals normalised, wall names set and (with
``facility.round_delays``) delays rounded to whole periods. ``Scenario.to_toml()`` writes
that resolved form, and loading it again gives an identical scenario.
"""

from __future__ import annotations

import copy
import difflib
import json
import math
import os
import re
import tomllib
from collections.abc import Mapping
from importlib import resources
from typing import Annotated, Any, Literal, Union

import tomli_w
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    ValidationError,
    field_validator,
    model_validator,
)

from .errors import ScenarioError
from .registry import KINDS

__all__ = [
    "COMPENSATOR_MODELS",
    "Body",
    "Contact",
    "DacCompensator",
    "Facility",
    "Metrics",
    "NoneCompensator",
    "PicCompensator",
    "PidaCompensator",
    "Rod",
    "Scenario",
    "Simulation",
    "TdpaAdmittanceCompensator",
    "TdpaImpedanceCompensator",
    "Wall",
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
        text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _fmt(value: float) -> str:
    """A float as a short decimal, for messages and rounded values."""
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


def _normalised(vector: list[float], norm: float) -> list[float]:
    # Idempotent: an already (numerically) unit vector is kept bit for bit, so that writing
    # the resolved scenario and loading it again gives an identical scenario.
    if abs(norm - 1.0) <= 1e-12:
        return vector
    return [v / norm for v in vector]


def _unit_vec3(value: Any) -> list[float]:
    vector = _vec3(value)
    norm = math.sqrt(sum(v * v for v in vector))
    if norm < 1e-12:
        raise ValueError(f"must be a nonzero vector (it is normalised), got {_show(vector)}")
    return _normalised(vector, norm)


def _quaternion(value: Any) -> list[float]:
    q = _numbers(value, 4, "a quaternion [w, x, y, z] (4 numbers)")
    norm = math.sqrt(sum(v * v for v in q))
    if norm < 1e-12:
        raise ValueError(f"must be a nonzero quaternion [w, x, y, z] (it is normalised), got {_show(q)}")
    return _normalised(q, norm)


_INERTIA_ALLOWED = (
    "3 principal moments [Ixx, Iyy, Izz] > 0 or a 3x3 symmetric positive-definite matrix (kg m^2)"
)


def _inertia(value: Any) -> list[list[float]]:
    value = _plain(value)
    if isinstance(value, list) and len(value) == 3 and all(_is_number(v) for v in value):
        moments = _vec3(value)
        if not all(m > 0 for m in moments):
            raise ValueError(f"principal moments must all be > 0, got {_show(value)}")
        return [[moments[i] if i == j else 0.0 for j in range(3)] for i in range(3)]
    if isinstance(value, list) and len(value) == 3 and all(isinstance(r, list) for r in value):
        try:
            rows = [_vec3(row) for row in value]
        except ValueError:
            raise ValueError(f"expected {_INERTIA_ALLOWED}, got {_show(value)}") from None
        scale = max(abs(v) for row in rows for v in row)
        for i in range(3):
            for j in range(i + 1, 3):
                if abs(rows[i][j] - rows[j][i]) > 1e-9 * scale:
                    raise ValueError(f"the 3x3 matrix must be symmetric, got {_show(value)}")
        # exact symmetrisation (idempotent for a symmetric matrix)
        m = [[rows[i][j] if i == j else 0.5 * (rows[i][j] + rows[j][i]) for j in range(3)] for i in range(3)]
        minors = (
            m[0][0],
            m[0][0] * m[1][1] - m[0][1] * m[1][0],
            m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]),
        )
        if not all(d > 0 for d in minors):
            raise ValueError(f"the 3x3 matrix must be positive definite, got {_show(value)}")
        return m
    raise ValueError(f"expected {_INERTIA_ALLOWED}, got {_show(value)}")


Vec3 = Annotated[list[float], BeforeValidator(_vec3)]
UnitVec3 = Annotated[list[float], BeforeValidator(_unit_vec3)]
Quaternion = Annotated[list[float], BeforeValidator(_quaternion)]
Inertia = Annotated[list[list[float]], BeforeValidator(_inertia)]


def _zeros() -> list[float]:
    return [0.0, 0.0, 0.0]


def _identity_quaternion() -> list[float]:
    return [1.0, 0.0, 0.0, 0.0]


# --------------------------------------------------------------------------------------
# Schema
# --------------------------------------------------------------------------------------


class _Table(BaseModel):
    """Base of every table: unknown keys are errors, no silent type coercion."""

    model_config = ConfigDict(extra="forbid", strict=True)


class Simulation(_Table):
    """``[simulation]``: time base and numerical settings."""

    duration: float = Field(gt=0, allow_inf_nan=False, description="s, > 0")
    period: float = Field(gt=0, allow_inf_nan=False, description="control period T in s, > 0")
    plant_substeps: int = Field(10, ge=1, description="facility sub-steps per period, integer >= 1")
    reference_substeps: int = Field(
        2, ge=1, description="RK4 steps per period for the ideal reference in contact, integer >= 1"
    )
    divergence_energy_ratio: float = Field(
        100.0, gt=1, allow_inf_nan=False, description="energy / initial energy that counts as diverged, > 1"
    )


class Body(_Table):
    """``[servicer]`` / ``[target]``: one free-floating satellite and its state at t = 0.

    The target's body frame is the mockup frame ``t``."""

    mass: float = Field(gt=0, allow_inf_nan=False, description="kg, > 0")
    inertia: Inertia = Field(description=_INERTIA_ALLOWED)
    position: Vec3 = Field(default_factory=_zeros, description="centre of mass at t = 0, world frame, m, 3 numbers")
    orientation: Quaternion = Field(
        default_factory=_identity_quaternion, description="unit quaternion [w, x, y, z], body to world"
    )
    velocity: Vec3 = Field(default_factory=_zeros, description="centre-of-mass velocity, world frame, m/s, 3 numbers")
    angular_velocity: Vec3 = Field(default_factory=_zeros, description="rad/s in the body frame, 3 numbers")


class Rod(_Table):
    """``[rod]``: the docking rod carried by the servicer."""

    tip: Vec3 = Field(description="rod tip in the servicer body frame, m, 3 numbers [x, y, z]")


class Wall(_Table):
    """``[[walls]]``: a plane of the collision frame on the target (frame t)."""

    name: str = Field("", description="a name; defaults to wall<i>")
    point: Vec3 = Field(description="a point of the wall in m, 3 numbers [x, y, z]")
    normal: UnitVec3 = Field(description="nonzero vector pointing into free space, 3 numbers [x, y, z]")


class Contact(_Table):
    """``[contact]``: the true (physical) contact law."""

    model: Literal["linear", "hunt-crossley"] = Field("linear", description="'linear' or 'hunt-crossley'")
    stiffness: float = Field(
        gt=0, allow_inf_nan=False, description="N/m (linear) or N/m^n (hunt-crossley), > 0"
    )
    damping: float = Field(
        0.0, ge=0, allow_inf_nan=False, description="N s/m (linear) or N s/m^(n+1) (hunt-crossley), >= 0"
    )
    exponent: float = Field(1.5, gt=0, allow_inf_nan=False, description="hunt-crossley exponent n, > 0")


class Facility(_Table):
    """``[facility]``: the model of the ground facility (robot, sensor)."""

    robot_delay: float = Field(0.0, ge=0, allow_inf_nan=False, description="s, >= 0, whole number of periods")
    sensor_delay: float = Field(0.0, ge=0, allow_inf_nan=False, description="s, >= 0, whole number of periods")
    servo_frequency: float = Field(0.0, ge=0, allow_inf_nan=False, description="Hz, >= 0 (0 = no servo lag)")
    servo_damping: float = Field(0.7, gt=0, allow_inf_nan=False, description="damping ratio, > 0")
    sensor_noise: float = Field(0.0, ge=0, allow_inf_nan=False, description="N std per axis, >= 0")
    torque_noise: float = Field(0.0, ge=0, allow_inf_nan=False, description="N m std per axis, >= 0")
    force_resolution: float = Field(0.0, ge=0, allow_inf_nan=False, description="N, >= 0 (0 = none)")
    torque_resolution: float = Field(0.0, ge=0, allow_inf_nan=False, description="N m, >= 0 (0 = none)")
    sensor_position: Vec3 = Field(default_factory=_zeros, description="sensor origin in frame t, m")
    sensor_orientation: Quaternion = Field(
        default_factory=_identity_quaternion, description="unit quaternion [w, x, y, z], t from s"
    )
    seed: int = Field(0, ge=0, description="random seed, integer >= 0")
    round_delays: bool = Field(False, description="true or false")


class NoneCompensator(_Table):
    """``kind = "none"``: the measured wrench goes straight into the virtual dynamics."""

    kind: Literal["none"] = "none"


class _ModelParams(_Table):
    """Parameters of the identification-based compensators ``pic``, ``dac``, ``pida``
    (the core's ``ModelParams``): adaptive Kalman identification of the contact stiffness
    and damping, measurement-delay compensation, energy observer and controller."""

    kind: str = Field("", description="set by each compensator class")  # first in the TOML
    delay_mode: Literal["align", "lead"] = Field(
        "align",
        description="measurement-delay compensation: 'align' (identify against the kinematics "
        "from tau_p earlier, robust to noise) or 'lead' (the paper's eq. (6))",
    )
    contact_force: float = Field(3.0, gt=0, allow_inf_nan=False, description="N, > 0: in contact above this force")
    stiffness_initial: float = Field(1.0e5, gt=0, allow_inf_nan=False, description="initial k estimate, N/m, > 0")
    damping_initial: float = Field(0.0, ge=0, allow_inf_nan=False, description="initial c estimate, N s/m, >= 0")
    stiffness_std: float = Field(1.0e5, gt=0, allow_inf_nan=False, description="initial std of k, N/m, > 0")
    damping_std: float = Field(300.0, gt=0, allow_inf_nan=False, description="initial std of c, N s/m, > 0")
    stiffness_walk: float = Field(10.0, ge=0, allow_inf_nan=False, description="random walk of k per update, N/m, >= 0")
    damping_walk: float = Field(0.1, ge=0, allow_inf_nan=False, description="random walk of c per update, N s/m, >= 0")
    noise_std: float = Field(0.1, gt=0, allow_inf_nan=False, description="initial force-increment noise std, N, > 0")
    forgetting: float = Field(0.98, allow_inf_nan=False, description="Sage-Husa forgetting factor b, 0 < b < 1")
    alpha_max: float = Field(100000.0, gt=0, allow_inf_nan=False, description="largest amendment damping, N s/m, > 0")
    observer: Literal["work", "paper"] = Field(
        "work",
        description="energy observer: 'work' (work of the wrench held over each step, exact) or "
        "'paper' (eqs. (15), (16) as printed)",
    )

    @field_validator("forgetting")
    @classmethod
    def _check_forgetting(cls, value: float) -> float:
        if not 0.0 < value < 1.0:
            raise ValueError(f"must be between 0 and 1 (exclusive), got {_show(value)}")
        return value


class PicCompensator(_ModelParams):
    """``kind = "pic"``: parameter identification control (the paper's Algorithm 1)."""

    kind: Literal["pic"] = "pic"


class DacCompensator(_ModelParams):
    """``kind = "dac"``: damping amendment control (Algorithm 2)."""

    kind: Literal["dac"] = "dac"


class PidaCompensator(_ModelParams):
    """``kind = "pida"``: identification and damping amendment (Algorithm 3)."""

    kind: Literal["pida"] = "pida"


class _TdpaParams(_Table):
    """Parameters of the time-domain passivity baselines (the core's ``TdpaParams``)."""

    kind: str = Field("", description="set by each compensator class")  # first in the TOML
    contact_force: float = Field(
        3.0, gt=0, allow_inf_nan=False, description="N, > 0: in contact above this force (the observer restarts)"
    )
    alpha_max: float = Field(100000.0, gt=0, allow_inf_nan=False, description="largest damping (impedance type), N s/m, > 0")
    beta_max: float = Field(1e-4, gt=0, allow_inf_nan=False, description="largest admittance (admittance type), m/(N s), > 0")
    velocity_floor: float = Field(1e-3, gt=0, allow_inf_nan=False, description="floor on |v| in a division, m/s, > 0")
    force_floor: float = Field(1.0, gt=0, allow_inf_nan=False, description="floor on |f| in a division, N, > 0")


class TdpaImpedanceCompensator(_TdpaParams):
    """``kind = "tdpa-impedance"``: time-domain passivity, impedance type (a series damper)."""

    kind: Literal["tdpa-impedance"] = "tdpa-impedance"


class TdpaAdmittanceCompensator(_TdpaParams):
    """``kind = "tdpa-admittance"``: time-domain passivity, admittance type (a damper on the
    velocity command)."""

    kind: Literal["tdpa-admittance"] = "tdpa-admittance"


# To add a compensator: define a _Table subclass with `kind: Literal["<kind>"] = "<kind>"` and
# its own parameters, and append it here. Everything else (the tagged union, error messages
# listing the allowed kinds and keys, the kind switch of overrides) derives from this tuple.
_COMPENSATOR_CLASSES: tuple[type[_Table], ...] = (
    NoneCompensator,
    PicCompensator,
    DacCompensator,
    PidaCompensator,
    TdpaImpedanceCompensator,
    TdpaAdmittanceCompensator,
)

_MODELS_BY_KIND = {cls.model_fields["kind"].default: cls for cls in _COMPENSATOR_CLASSES}
if set(_MODELS_BY_KIND) != set(KINDS):  # pragma: no cover - a registry change without its schema
    raise ImportError(
        f"the scenario schema's compensator kinds {sorted(_MODELS_BY_KIND)} differ from the "
        f"core's registry {sorted(KINDS)}"
    )
COMPENSATOR_MODELS: dict[str, type[_Table]] = {kind: _MODELS_BY_KIND[kind] for kind in KINDS}
"""The schema of each compensator kind's table, in the core registry's order."""


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


class Metrics(_Table):
    """``[metrics]``: how collisions are detected for the metrics."""

    contact_threshold: float = Field(0.5, gt=0, allow_inf_nan=False, description="N, > 0")


_TABLES: dict[str, Any] = {
    "simulation": Simulation,
    "servicer": Body,
    "target": Body,
    "rod": Rod,
    "walls": Wall,
    "contact": Contact,
    "facility": Facility,
    "compensator": COMPENSATOR_MODELS,  # tagged: the member depends on `kind`
    "metrics": Metrics,
}


class Scenario(_Table):
    """A fully resolved scenario. Build it with :func:`load_scenario` or :meth:`from_dict`."""

    name: str = Field(description="the scenario's name, a string")
    description: str = Field("", description="a string")
    simulation: Simulation
    servicer: Body
    target: Body
    rod: Rod
    walls: list[Wall] = Field(min_length=1)
    contact: Contact
    facility: Facility = Field(default_factory=Facility)
    compensator: Compensator = Field(default_factory=NoneCompensator)  # type: ignore[valid-type]
    metrics: Metrics = Field(default_factory=Metrics)

    @field_validator("name")
    @classmethod
    def _check_name(cls, name: str) -> str:
        if not name.strip() or name.strip() in (".", "..") or "/" in name or "\\" in name:
            raise ValueError(f"must be a non-empty name without '/' or '\\' (it names the output folder), got {name!r}")
        return name

    @model_validator(mode="after")
    def _resolve(self) -> Scenario:
        seen: dict[str, int] = {}
        for i, wall in enumerate(self.walls):
            if not wall.name:
                wall.name = f"wall{i}"
            if wall.name in seen:
                raise ValueError(
                    f"walls[{i}].name: duplicate wall name {wall.name!r} (also walls[{seen[wall.name]}])"
                )
            seen[wall.name] = i

        period = self.simulation.period
        if self.simulation.duration < period:
            raise ValueError(
                f"simulation.duration = {_fmt(self.simulation.duration)} s is shorter than one period "
                f"(simulation.period = {_fmt(period)} s)"
            )
        for key in ("robot_delay", "sensor_delay"):
            delay = getattr(self.facility, key)
            ratio = delay / period
            n = math.floor(ratio + 0.5)
            if self.facility.round_delays:
                setattr(self.facility, key, float(_fmt(n * period)))
            elif abs(ratio - n) > 1e-9 * max(1.0, ratio):
                lo = math.floor(ratio)
                raise ValueError(
                    f"facility.{key} = {_fmt(delay)} s is not a whole number of periods "
                    f"(simulation.period = {_fmt(period)} s): use {_fmt(lo * period)} or "
                    f"{_fmt((lo + 1) * period)}, or set facility.round_delays = true"
                )
        return self

    # ---- construction ------------------------------------------------------------------

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Scenario:
        """Validate a raw (TOML-shaped) dict; raise ScenarioError with a one-line message."""
        try:
            return cls.model_validate(_plain(data))
        except ValidationError as exc:
            raise ScenarioError(_format_validation_error(exc)) from None

    @classmethod
    def from_toml(cls, text: str, source: str = "<string>") -> Scenario:
        """Parse and validate TOML text."""
        return cls.from_dict(_parse_toml(text, source))

    # ---- output ------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """The resolved scenario as plain data (the schema of the TOML file and of the JSON)."""
        return self.model_dump(mode="json")

    def to_json(self) -> str:
        """The resolved scenario as JSON, the input of ``hilcontact._core.simulate``."""
        return json.dumps(self.to_dict())

    def to_toml(self) -> str:
        """The fully resolved scenario as TOML; loading it again gives an identical Scenario."""
        from . import __version__

        header = (
            f"# Resolved scenario {self.name!r}, written by hilcontact {__version__}.\n"
            "# Every value is explicit (defaults filled in); SI units, frames as in the docs.\n"
        )
        return header + _compact_arrays(tomli_w.dumps(self.to_dict()))


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
        else:
            current = None
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
        hint = f" ({field.description})" if field is not None and field.description else ""
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
    if kind == "finite_number":
        return at(f"must be a finite number, got {_show(value)}")
    bounds = {"greater_than": ("gt", ">"), "greater_than_equal": ("ge", ">="),
              "less_than": ("lt", "<"), "less_than_equal": ("le", "<=")}
    if kind in bounds:
        name, op = bounds[kind]
        bound = ctx.get(name)
        shown = _fmt(bound) if _is_number(bound) else _show(bound)
        return at(f"must be {op} {shown}, got {_show(value)}")
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


def _format_validation_error(exc: ValidationError) -> str:
    lines: list[str] = []
    for err in exc.errors(include_url=False):
        line = _error_line(err)
        if line not in lines:
            lines.append(line)
    if not lines:  # pragma: no cover - pydantic always reports something
        return "invalid scenario"
    message = lines[0]
    if len(lines) > 1:
        others = [line.split(":", 1)[0] for line in lines[1:]]
        message += f" (and {len(lines) - 1} more: {', '.join(others)})"
    return message


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
        if isinstance(last, int):
            if last >= len(node):
                raise ScenarioError(f"{key}: {_dotted(steps[:-1])} has only {len(node)} item(s)")
            node[last] = _plain(value)
        else:
            node[last] = _plain(value)
    return data


def _read_source(source: Any) -> dict[str, Any]:
    if isinstance(source, Scenario):
        return source.to_dict()
    if isinstance(source, Mapping):
        return copy.deepcopy(dict(source))
    if not isinstance(source, (str, os.PathLike)):
        raise ScenarioError(f"expected a preset name, a TOML file path or a Scenario, got {_show(source)}")
    text = os.fspath(source)
    files = _preset_files()
    if isinstance(source, str) and text in files:
        return _parse_toml(files[text].read_text(encoding="utf-8"), f"preset {text!r}")
    if os.path.isfile(text):
        try:
            with open(text, "rb") as handle:
                content = handle.read().decode("utf-8")
        except UnicodeDecodeError:
            raise ScenarioError(f"{text}: not a UTF-8 text file") from None
        except OSError as exc:
            raise ScenarioError(f"{text}: cannot read: {exc.strerror}") from None
        return _parse_toml(content, text)
    if os.path.isdir(text):
        raise ScenarioError(f"{text}: is a directory, expected a preset name or a TOML file")
    names = ", ".join(sorted(files)) or "(none)"
    raise ScenarioError(f"unknown scenario {text!r}: not a preset and no such file; presets: {names}")


def load_scenario(source: Any, overrides: Mapping[str, Any] | None = None) -> Scenario:
    """Load and validate a scenario.

    ``source`` is a preset name (see :func:`presets`), a path to a TOML file, a raw dict or a
    :class:`Scenario`. ``overrides`` maps dotted keys (``"facility.robot_delay"``) to values and
    is applied to the raw TOML data before validation. Raises ScenarioError.
    """
    raw = _read_source(source)
    if overrides:
        raw = apply_overrides(raw, overrides)
    return Scenario.from_dict(raw)
