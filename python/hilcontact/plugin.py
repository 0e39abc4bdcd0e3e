"""Your own compensator, written in Python, in the same HIL loop as the shipped ones.

Subclass :class:`Compensator` and implement :meth:`Compensator.step` (and
:meth:`Compensator.reset` if it keeps state)::

    import hilcontact as hc

    class PassThrough(hc.Compensator):
        def step(self, inp):
            return {"applied_force": inp.measured_force, "applied_moment": inp.measured_moment}

    run = hc.simulate("paper-table1", compensator=PassThrough)

It mirrors the core's Rust ``Compensator`` trait (``crates/core/src/compensator/mod.rs``): the
loop calls ``reset(context)`` once before a run, then ``step(inp)`` once per control tick,
between the sensor and the virtual dynamics; what it returns is applied to the virtual
satellites. On the command line a compensator is named by its entry, ``path/to/file.py:Class``
or ``package.module:Class`` (``--compensator`` on ``run``, ``compare``, ``sweep`` and
``benchmark``; ``compensator.kind = "python"`` with ``compensator.entry`` in a scenario).

A step that raises, returns a non-finite number or a wrong shape, or takes longer than the time
limit (:data:`STEP_LIMIT`) stops the run: :class:`PluginError` (a ``ScenarioError``: the CLI
prints its one line and exits with 2, writing nothing) names the class and the tick. See
docs/compensators/python.md.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import math
import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from .errors import ScenarioError

__all__ = [
    "STEP_LIMIT",
    "Compensator",
    "Context",
    "PluginError",
    "StepInput",
    "StepOutput",
    "load_compensator",
]

#: Default longest wall time one ``step`` may take, s (generous: a step in Python takes tens of
#: microseconds; docs/compensators/python.md).
STEP_LIMIT = 0.5


class PluginError(ScenarioError):
    """A Python compensator cannot be loaded or misbehaved during a run (one line naming the
    class and, during a run, the tick). A ``ScenarioError``: the CLI exits with 2."""


@dataclass(frozen=True)
class Context:
    """The fixed facts a compensator may use, given to :meth:`Compensator.reset` (as the Rust
    ``CompensatorContext``)."""

    period: float
    """Control period T, s."""
    sensor_delay_ticks: int
    """Known sensor delay τ_p, control ticks."""
    sensor_delay: float
    """Known sensor delay τ_p, s."""
    sensor_origin: np.ndarray
    """Sensor origin in the target frame ``t``, m (3)."""
    sensor_orientation: np.ndarray
    """Sensor attitude in ``t`` (sensor to ``t``), unit quaternion [w, x, y, z]."""
    sensor_rotation: np.ndarray
    """The same attitude as a 3x3 rotation matrix: ``sensor_rotation @ f`` turns a vector of
    the sensor frame into ``t``; ``sensor_rotation.T @ v`` the other way."""
    reduced_mass: float
    """Reduced mass of the virtual satellites μ = m_s m_t / (m_s + m_t), kg."""
    scenario: Any
    """The resolved :class:`~hilcontact.Scenario` (its nominal values: ``scenario.contact``,
    ``scenario.facility``, ...). What the loop cannot know on a real facility (the true
    contact, the robot delay) is there too: a compensator that reads it is not deployable."""


@dataclass(slots=True)
class StepInput:
    """What a compensator sees at one tick (as the Rust ``CompensatorInput``, the wrench in the
    sensor frame). New arrays each tick: a compensator may keep them."""

    tick: int
    """Tick number k, from 0."""
    time: float
    """Time k·T, s."""
    measured_force: np.ndarray
    """Measured force on the frame, sensor frame, N (3)."""
    measured_moment: np.ndarray
    """Measured moment about the sensor origin, sensor frame, N·m (3)."""
    tip_position_actual: np.ndarray
    """Actual rod tip (robot), ``t`` frame, m (3)."""
    tip_velocity_actual: np.ndarray
    """Actual rod tip velocity, ``t`` frame, m/s (3)."""
    tip_position_desired: np.ndarray
    """Desired rod tip (virtual dynamics), ``t`` frame, m (3)."""
    tip_velocity_desired: np.ndarray
    """Desired rod tip velocity, ``t`` frame, m/s (3)."""
    tip_mobility: np.ndarray
    """Mobility K of the virtual rod tip, 1/kg (3x3, ``t``): an impulse J at the tip changes
    the desired tip velocity by K·J; zeros unless the class sets ``uses_tip_mobility``."""


@dataclass(slots=True)
class StepOutput:
    """What a compensator returns at a tick (a plain dict with these keys works too)."""

    applied_force: Any
    """Force applied to the virtual dynamics, sensor frame and convention, N (3 numbers)."""
    applied_moment: Any
    """Moment applied, about the sensor origin, sensor frame, N·m (3 numbers)."""
    velocity_correction: Any = field(default=(0.0, 0.0, 0.0))
    """Change of the virtual rod tip's velocity, ``t`` frame, m/s (3; an impulse at the tip)."""
    stiffness_estimate: float = math.nan
    """Identified stiffness, N/m (NaN: none; recorded when ``estimates_contact``)."""
    damping_estimate: float = math.nan
    """Identified damping, N·s/m (NaN: none; recorded when ``estimates_contact``)."""
    observed_energy: float = math.nan
    """Energy observed at the environment port, J (NaN: none; recorded when ``observes_energy``)."""


class Compensator:
    """Base class of a compensator written in Python (see the module doc).

    Class attributes, as the Rust trait's methods of the same names: ``estimates_contact``
    (``step`` returns stiffness and damping estimates), ``observes_energy`` (it returns an
    observed energy), ``uses_tip_mobility`` (it reads ``inp.tip_mobility``, computed only
    then). ``name`` is what metrics and tables call it (default: the class name).
    """

    estimates_contact: bool = False
    observes_energy: bool = False
    uses_tip_mobility: bool = False
    name: str | None = None

    def reset(self, context: Context) -> None:
        """Forget all state before a run; ``context`` holds the run's fixed facts."""
        self.context = context

    def step(self, inp: StepInput) -> StepOutput | Mapping[str, Any]:  # pragma: no cover - abstract
        """One control tick: the wrench to apply (sensor frame) and optional extras."""
        raise NotImplementedError(f"{type(self).__name__}.step")


# ---- loading -------------------------------------------------------------------------------

def _load_module(source: str) -> Any:
    if source.endswith(".py") or os.sep in source or "/" in source:
        path = Path(source)
        if not path.is_file():
            raise PluginError(f"compensator {source}: no such file")
        name = f"hilcontact_plugin_{abs(hash(str(path.resolve())))}"
        if name in sys.modules:
            return sys.modules[name]
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            raise PluginError(f"compensator {source}: not a Python file")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except Exception as exc:
            del sys.modules[name]
            raise PluginError(f"compensator {source}: importing it raised {_describe(exc)}") from exc
        return module
    try:
        return importlib.import_module(source)
    except ModuleNotFoundError as exc:
        if exc.name and source.startswith(exc.name):
            raise PluginError(f"compensator {source}: no such module") from None
        raise PluginError(f"compensator {source}: importing it raised {_describe(exc)}") from exc
    except Exception as exc:
        raise PluginError(f"compensator {source}: importing it raised {_describe(exc)}") from exc


def load_compensator(entry: Any) -> type[Compensator]:
    """The compensator class named by ``entry``: ``"path/to/file.py:ClassName"``,
    ``"package.module:ClassName"``, or a :class:`Compensator` subclass itself. Raises
    :class:`PluginError` (one line) for a missing file, module or class, or a class that is
    not a :class:`Compensator` with a ``step``."""
    if inspect.isclass(entry):
        cls = entry
        where = f"{cls.__module__}:{cls.__qualname__}"
    else:
        if not isinstance(entry, str) or ":" not in entry:
            raise PluginError(
                f"compensator {entry!r}: expected path/to/file.py:ClassName or module:ClassName"
            )
        source, _, name = entry.rpartition(":")
        if not source or not name:
            raise PluginError(f"compensator {entry!r}: expected path/to/file.py:ClassName or module:ClassName")
        module = _load_module(source)
        cls = getattr(module, name, None)
        where = entry
        if cls is None:
            found = sorted(n for n, v in vars(module).items()
                           if inspect.isclass(v) and issubclass(v, Compensator) and v is not Compensator)
            hint = f"; it has {', '.join(found)}" if found else ""
            raise PluginError(f"compensator {entry}: {source} has no class {name}{hint}")
    if not (inspect.isclass(cls) and issubclass(cls, Compensator)):
        raise PluginError(f"compensator {where}: not a subclass of hilcontact.Compensator")
    if cls.step is Compensator.step:
        raise PluginError(f"compensator {where}: {cls.__name__} does not define step(self, inp)")
    return cls


def compensator_name(entry: Any) -> str:
    """What runs and tables call the compensator of ``entry``: its class's ``name`` or the
    class name, prefixed ``py:`` so it never reads as a shipped kind."""
    cls = load_compensator(entry)
    return "py:" + (cls.name or cls.__name__)


# ---- the adapter the core calls ------------------------------------------------------------

def _describe(exc: BaseException) -> str:
    return " ".join(f"{type(exc).__name__}: {exc}".split())


def _vector(value: Any, key: str, where: str) -> tuple[float, float, float]:
    """Three finite numbers of a returned 3-sequence, or PluginError naming the key."""
    if value is None:
        raise PluginError(f"{where} returned no {key} (return a dict or a StepOutput with {key})")
    try:
        wrong = len(value) != 3 or isinstance(value, str) or (isinstance(value, np.ndarray) and value.ndim != 1)
        if not wrong:
            x, y, z = float(value[0]), float(value[1]), float(value[2])
    except (TypeError, ValueError):
        raise PluginError(f"{where} returned {key} = {value!r:.60}, expected 3 numbers") from None
    if wrong:
        raise PluginError(f"{where} returned {key} of shape {np.shape(value)}, expected 3 numbers")
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        raise PluginError(f"{where} returned a non-finite {key} {[x, y, z]}")
    return x, y, z

_SCALARS = ("stiffness_estimate", "damping_estimate", "observed_energy")


class _Adapter:
    """What ``_core.simulate_python`` drives: builds the context and each tick's
    :class:`StepInput` from the core's numbers, calls the user's compensator, times it and
    checks what it returns (one :class:`PluginError` naming class and tick)."""

    def __init__(self, compensator: Compensator, scenario: Any, step_limit: float = STEP_LIMIT) -> None:
        self.compensator = compensator
        self.label = type(compensator).__name__
        self.scenario = scenario
        self.step_limit = float(step_limit)
        self.estimates_contact = bool(compensator.estimates_contact)
        self.observes_energy = bool(compensator.observes_energy)
        self.uses_tip_mobility = bool(compensator.uses_tip_mobility)
        self.period = 0.0
        #: Set by a Ctrl-C during the run (:func:`stop_on_interrupt`): ``_core.simulate_python``
        #: reads it after each tick and ends the run there, as ``interrupted``.
        self.interrupted = False

    def reset(self, context: Mapping[str, Any]) -> None:
        self.period = float(context["period"])
        rotation = np.asarray(context["sensor_rotation"], dtype=np.float64).reshape(3, 3)
        ctx = Context(
            period=self.period,
            sensor_delay_ticks=int(context["sensor_delay_ticks"]),
            sensor_delay=float(context["sensor_delay"]),
            sensor_origin=np.asarray(context["sensor_origin"], dtype=np.float64),
            sensor_orientation=np.asarray(context["sensor_orientation"], dtype=np.float64),
            sensor_rotation=rotation,
            reduced_mass=float(context["reduced_mass"]),
            scenario=self.scenario,
        )
        try:
            self.compensator.reset(ctx)
        except Exception as exc:
            raise PluginError(f"compensator {self.label}.reset raised {_describe(exc)}") from exc

    def step_flat(self, k: int, data: tuple[float, ...]) -> tuple[float, ...]:
        a = np.asarray(data, dtype=np.float64)
        inp = StepInput(
            tick=k, time=float(a[0]), measured_force=a[1:4], measured_moment=a[4:7],
            tip_position_actual=a[7:10], tip_velocity_actual=a[10:13],
            tip_position_desired=a[13:16], tip_velocity_desired=a[16:19],
            tip_mobility=a[19:28].reshape(3, 3),
        )
        where = f"compensator {self.label}.step at tick {k} (t = {inp.time:.6g} s)"
        start = time.perf_counter()
        try:
            out = self.compensator.step(inp)
        except Exception as exc:
            raise PluginError(f"{where} raised {_describe(exc)}") from exc
        spent = time.perf_counter() - start
        if spent > self.step_limit:
            raise PluginError(f"{where} took {spent:.3g} s, above the limit of {self.step_limit:g} s (--step-limit)")
        if isinstance(out, dict) or isinstance(out, Mapping):
            get = out.get
        else:
            def get(key: str, default: Any = None) -> Any:
                return getattr(out, key, default)
        force = get("applied_force", None)
        moment = get("applied_moment", None)
        correction = get("velocity_correction", None)
        values = [
            *_vector(force, "applied_force", where),
            *_vector(moment, "applied_moment", where),
            *((0.0, 0.0, 0.0) if correction is None else _vector(correction, "velocity_correction", where)),
        ]
        for key in _SCALARS:
            value = get(key, None)
            try:
                number = math.nan if value is None else float(value)
            except (TypeError, ValueError):
                raise PluginError(f"{where} returned {key} = {value!r:.60}, expected a number") from None
            if math.isinf(number):
                raise PluginError(f"{where} returned an infinite {key}")
            values.append(number)
        return tuple(values)


def _interrupts(number: int, handler: Any) -> bool:
    """Whether a Python signal handler turns its signal into KeyboardInterrupt: Python's own
    Ctrl-C handler, or the one the ``hilcontact`` commands give SIGTERM."""
    if handler is signal.default_int_handler:
        return True
    options = sys.modules.get("hilcontact.cli.options")
    return number == signal.SIGTERM and options is not None and handler is getattr(
        options, "_raise_keyboard_interrupt", None)


@contextmanager
def stop_on_interrupt(adapter: _Adapter) -> Iterator[None]:
    """While a run with a Python compensator runs in the main thread: the first Ctrl-C (or a
    SIGTERM the command turns into one) sets ``adapter.interrupted`` instead of raising
    KeyboardInterrupt inside the compensator's ``step``; the core's loop then ends the run at
    that tick and returns it as ``interrupted``, as it does a native run. The handlers are
    given back then, so that a second one raises KeyboardInterrupt as usual. Elsewhere (another
    thread, handlers of the user's own) nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {n: signal.getsignal(n) for n in (signal.SIGINT, signal.SIGTERM)}
    replaced = {n: h for n, h in previous.items() if _interrupts(n, h)}

    def restore() -> None:
        for number, handler in replaced.items():
            if signal.getsignal(number) is stop:
                signal.signal(number, handler)

    def stop(_signum: int, _frame: Any) -> None:
        adapter.interrupted = True
        restore()

    for number in replaced:
        signal.signal(number, stop)
    try:
        yield
    finally:
        restore()


def make_adapter(entry: Any, scenario: Any, step_limit: float = STEP_LIMIT) -> _Adapter:
    """The adapter of a new instance of the compensator of ``entry`` (see
    :func:`load_compensator`) for a run of ``scenario``."""
    if not (isinstance(step_limit, (int, float)) and not isinstance(step_limit, bool)
            and math.isfinite(step_limit) and step_limit > 0):
        raise ScenarioError(f"step_limit: expected a number of seconds > 0, got {step_limit!r}")
    cls = load_compensator(entry)
    try:
        instance = cls()
    except Exception as exc:
        raise PluginError(f"compensator {cls.__name__}(): creating it raised {_describe(exc)}") from exc
    return _Adapter(instance, scenario, step_limit)


#: The columns a replay returns (as ``_core.replay``'s): time, the applied wrench in the sensor
#: frame, the velocity correction, the estimates and the observed energy.
_REPLAY_VECTORS = ("applied_force", "applied_moment", "velocity_correction")


def replay(entry: Any, scenario: Any, data: Any, step_limit: float = STEP_LIMIT) -> Any:
    """A Python compensator run open loop on a recording, as ``_core.replay`` runs a shipped
    one: ``data`` (a DataFrame) has ``time``, ``measured_force_*``, ``measured_moment_*`` (sensor
    frame), ``actual_tip_position_*``, ``actual_tip_velocity_*``, ``tip_position_*``,
    ``tip_velocity_*`` (``t``); the tip's mobility is ``I/μ`` (as the core's replay). Returns a
    DataFrame of time, applied_force_*, applied_moment_* (sensor frame), velocity_correction_*,
    stiffness_estimate, damping_estimate, observed_energy. PluginError as in a run."""
    import pandas as pd

    from .native import core

    adapter = make_adapter(entry, scenario, step_limit)
    context = core().compensator_context(scenario.to_json())
    adapter.reset(context)
    axes = ("x", "y", "z")
    names = ["time"] + [f"{group}_{a}" for group in ("measured_force", "measured_moment", "actual_tip_position",
                                                      "actual_tip_velocity", "tip_position", "tip_velocity")
                        for a in axes]
    rows = data[names].to_numpy(dtype=np.float64)
    mobility = tuple((np.eye(3) / float(context["reduced_mass"])).ravel())
    out = np.empty((len(rows), 13))
    for k, row in enumerate(rows):
        out[k, 0] = row[0]
        out[k, 1:] = adapter.step_flat(k, (*row, *mobility))
    columns = ["time"] + [f"{group}_{a}" for group in _REPLAY_VECTORS for a in axes] + list(_SCALARS)
    return pd.DataFrame(out, columns=columns)


def with_python_compensators(scenarios: Mapping[str, Any], entries: Sequence[Any]) -> dict[str, Any]:
    """A comparison's scenarios (name -> Scenario, as ``comparison_scenarios`` gives them) with
    one more per Python compensator of ``entries``, named ``py:<Class>``: the first scenario
    with ``compensator.kind = "python"`` and the entry (``simulate`` then runs it)."""
    out = dict(scenarios)
    base = next(iter(scenarios.values()))
    for entry in entries:
        name = compensator_name(entry)
        if name in out:
            raise PluginError(f"compensator {entry}: {name} is compared twice")
        scenario = base.model_copy()
        scenario._python_entry = entry
        out[name] = scenario
    return out


def run_summaries(scenarios: Sequence[str], step_limit: float = STEP_LIMIT) -> dict[str, list[Any]]:
    """Runs scenarios (JSON of resolved scenarios with ``compensator.kind = "python"``) one
    after the other in this process and returns their sweep rows as ``_core.simulate_batch``
    does: ``status`` and one list per column of ``_core.summary_columns()`` (``wall_time``
    included, s). Holds the GIL while the compensator steps: threads do not run two at once,
    processes (Dask workers) do."""
    import json as _json

    from .native import core
    from .scenario import Scenario

    names = [name for name, _, _ in core().summary_columns()]
    columns: dict[str, list[Any]] = {"status": [], **{name: [] for name in names}}
    for text in scenarios:
        scenario = Scenario.from_dict(_json.loads(text))
        entry = scenario.python_entry
        adapter = make_adapter(entry, scenario, step_limit)
        start = time.perf_counter()
        result = core().simulate_python(scenario.to_json(), adapter, compensator_name(entry))
        wall_time = time.perf_counter() - start
        summary = result["summary"]
        columns["status"].append(str(summary["status"]))
        for name in names:
            columns[name].append(wall_time if name == "wall_time" else float(summary[name]))
    return columns
