"""Your own data: read a recording (a run folder, a CSV or Parquet file, a ROS 2 bag), replay
a compensator on it, identify its contacts.

Columns (one row per control tick; names as in a run's ``timeseries.parquet``):

============================  =====  =======  ===================================================
column                        unit   frame    meaning
============================  =====  =======  ===================================================
``time``                      s               strictly increasing, one control period apart
``measured_force_{x,y,z}``    N      sensor   force on the frame, as the sensor reports it
``measured_moment_{x,y,z}``   N m    sensor   moment about the sensor origin
``actual_tip_position_*``     m      ``t``    the robot's rod tip (forward kinematics)
``actual_tip_velocity_*``     m/s    ``t``    its velocity
``tip_position_*``            m      ``t``    desired (virtual) rod tip: replay only
``tip_velocity_*``            m/s    ``t``    its velocity: replay only
============================  =====  =======  ===================================================

The rest (sensor pose and delay, period, the compensator's parameters) comes from a scenario:
a run folder's own ``scenario.toml``, else ``--scenario FILE``, else the ``paper-table1`` preset; the period is
taken from the recording's time steps when they differ from the scenario's.

Velocities are optional for ``identify`` (CSV, Parquet, bags without a twist topic): without
them they are the positions' derivative by second-order central differences on the sample
times (:func:`differentiate`, ``numpy.gradient``; no smoothing). Moments are optional for
``identify`` too (taken as zero: they do not enter the identification). ``--columns`` maps a
lab's own column names, signs and units (:func:`parse_columns`). An ``.mcap`` file (the
project's own ``--mcap`` recording, or a ROS 2 bag in MCAP) is read with its topics; the
project's own gives its scenario too. See docs/identification.md.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .errors import ScenarioError
from .native import core as _core
from .output import write_atomically
from .scenario import Scenario, load_scenario

__all__ = [
    "DESIRED_COLUMNS", "IDENTIFY_COLUMNS", "OFFLINE_FORGETTING", "RecordingError", "Recording",
    "Finding", "check_plausibility", "differentiate", "identify", "parse_columns", "read_recording",
    "replay",
]

_AXES = ("x", "y", "z")


def _vec(name: str) -> list[str]:
    return [f"{name}_{a}" for a in _AXES]


#: Columns that identification needs (replay needs :data:`DESIRED_COLUMNS` too).
IDENTIFY_COLUMNS: list[str] = [
    "time", *_vec("measured_force"), *_vec("measured_moment"),
    *_vec("actual_tip_position"), *_vec("actual_tip_velocity"),
]
#: The desired (virtual) rod tip, for replay.
DESIRED_COLUMNS: list[str] = [*_vec("tip_position"), *_vec("tip_velocity")]
#: The scenario of a recording that is not a run folder, without ``--scenario``.
DEFAULT_SCENARIO = "paper-table1"
#: Forgetting factor of the noise estimate used by ``identify`` unless told otherwise (the
#: core's ``identify::OFFLINE_FORGETTING``; see docs/identification.md).
OFFLINE_FORGETTING = 0.9


class RecordingError(ScenarioError):
    """A recording that cannot be used: missing columns or topics, NaN samples, time not
    increasing, too short. The message is one line naming the file and the problem."""


@dataclass
class Recording:
    """A recording's columns and the scenario that gives the rest."""

    source: str
    data: pd.DataFrame
    scenario: Scenario
    #: What was derived rather than read (e.g. "actual_tip_velocity_*: differentiated from
    #: the position"), in order.
    derived: list[str] = field(default_factory=list)
    #: The ``--columns`` mapping used (canonical name -> (source column, sign, unit)).
    mapping: dict[str, tuple[str, float, str]] = field(default_factory=dict)

    def columns(self, names: list[str]) -> dict[str, np.ndarray]:
        return {n: np.ascontiguousarray(self.data[n].to_numpy(dtype=np.float64)) for n in names}


def _read_table(path: Path) -> pd.DataFrame:
    try:
        if path.suffix.lower() == ".csv":
            return pd.read_csv(path)
        return pd.read_parquet(path)
    except (OSError, ValueError) as exc:
        raise RecordingError(f"{path}: unreadable ({' '.join(str(exc).split())})") from None


def _stamp(msg: Any, fallback_ns: int) -> int:
    """The message's header stamp in integer ns (the bag's receive time if it has none)."""
    header = getattr(msg, "header", None)
    if header is not None:
        ns = int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec)
        if ns > 0:
            return ns
    return int(fallback_ns)


#: The topics of the project's own MCAP recordings (``--mcap``; crates/rt/src/output/mcap.rs),
#: used by default when a file has them.
OWN_MCAP_TOPICS = {
    "wrench": "/hil/measured_wrench", "pose": "/hil/tip/actual", "twist": "/hil/tip/actual_velocity",
    "desired_pose": "/hil/tip/commanded", "desired_twist": "/hil/tip/commanded_velocity",
}


def differentiate(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The derivative of samples ``p`` (rows: samples; 1-D or 2-D) at times ``t`` (s) by
    second-order central differences on the (possibly uneven) sample times, first-order at the
    two ends (``numpy.gradient``); no smoothing: a position noise of σ gives a velocity noise
    of about σ/(√2·T)."""
    if p.ndim == 1:
        return np.gradient(p, t)
    return np.stack([np.gradient(p[:, i], t) for i in range(p.shape[1])], axis=1)


def _frame_from_topics(path: Path, topics: dict[str, str], series: Any, wrench_topic: str | None,
                       pose_topic: str | None, twist_topic: str | None, desired_pose_topic: str | None,
                       desired_twist_topic: str | None = None) -> pd.DataFrame:
    """The recording's columns from a bag's or MCAP file's WrenchStamped, PoseStamped (and
    TwistStamped) topics (``topics``: topic -> message type; ``series(topic, get)``: the
    topic's header stamps in integer ns and ``get(msg)`` rows), on the wrench's time base
    (pose linearly interpolated, velocity differentiated if no twist topic)."""

    def pick(topic: str | None, kind: str, option: str) -> str | None:
        if topic is not None:
            if topic not in topics:
                raise RecordingError(f"{path}: no topic {topic} ({option}); topics: {', '.join(sorted(topics)) or '(none)'}")
            return topic
        found = sorted(t for t, m in topics.items() if m.replace("/msg/", "/").endswith(kind))
        if len(found) == 1:
            return found[0]
        if kind == "TwistStamped":
            return None
        what = f"{len(found)} {kind} topics ({', '.join(found)})" if found else f"no {kind} topic"
        raise RecordingError(f"{path}: {what}; choose one with {option}")

    wrench = pick(wrench_topic, "WrenchStamped", "--wrench-topic")
    pose = pick(pose_topic, "PoseStamped", "--pose-topic")
    twist = pick(twist_topic, "TwistStamped", "--twist-topic")
    desired = pick(desired_pose_topic, "PoseStamped", "--desired-pose-topic") if desired_pose_topic else None

    def checked(topic: str, get: Any) -> tuple[np.ndarray, np.ndarray]:
        times, rows = series(topic, get)
        if len(rows) == 0:
            raise RecordingError(f"{path}: topic {topic} has no messages")
        return np.asarray(times, dtype=np.int64), np.asarray(rows, dtype=np.float64)

    def position(m: Any) -> list[float]:
        return [m.pose.position.x, m.pose.position.y, m.pose.position.z]

    def linear(m: Any) -> list[float]:
        return [m.twist.linear.x, m.twist.linear.y, m.twist.linear.z]

    tw, w = checked(wrench, lambda m: [m.wrench.force.x, m.wrench.force.y, m.wrench.force.z,
                                       m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z])
    tp, p = checked(pose, position)
    v = dv = None
    if twist is not None:
        tv, v = checked(twist, linear)
    elif len(tp) < 2:
        raise RecordingError(f"{path}: topic {pose} has fewer than 2 messages")
    else:
        tv = tp
    if desired is not None:
        td, d = checked(desired, position)
        if len(td) < 2:
            raise RecordingError(f"{path}: topic {desired} has fewer than 2 messages")
        if desired_twist_topic is not None and desired_twist_topic in topics:
            tdv, dv = checked(desired_twist_topic, linear)
    # seconds from the first wrench, exact in integer ns before the conversion
    start = tw[0]
    tw, tp, tv = ((t - start).astype(np.float64) * 1e-9 for t in (tw, tp, tv))
    for name, t in ((wrench, tw), (pose, tp)):
        if np.any(np.diff(t) <= 0):
            i = int(np.argmax(np.diff(t) <= 0)) + 1
            raise RecordingError(f"{path}: topic {name}: time is not strictly increasing at message {i}")
    if v is None:  # no twist topic: differentiate the pose
        v = differentiate(tp, p)
    if desired is not None:
        td = (td - start).astype(np.float64) * 1e-9
        if dv is None:
            tdv, dv = td, differentiate(td, d)
        else:
            tdv = (tdv - start).astype(np.float64) * 1e-9
    data: dict[str, np.ndarray] = {"time": tw}
    for i, a in enumerate(_AXES):
        data[f"measured_force_{a}"] = w[:, i]
        data[f"measured_moment_{a}"] = w[:, 3 + i]
        data[f"actual_tip_position_{a}"] = np.interp(tw, tp, p[:, i])
        data[f"actual_tip_velocity_{a}"] = np.interp(tw, tv, v[:, i])
        if desired is not None:
            data[f"tip_position_{a}"] = np.interp(tw, td, d[:, i])
            data[f"tip_velocity_{a}"] = np.interp(tw, tdv, dv[:, i])
    return pd.DataFrame(data)


def _read_bag(path: Path, wrench_topic: str | None, pose_topic: str | None,
              twist_topic: str | None, desired_pose_topic: str | None = None) -> pd.DataFrame:
    """A ROS 2 bag folder (sqlite3 or MCAP storage, with ``metadata.yaml``), read with
    ``rosbags``: see :func:`_frame_from_topics`; ``desired_pose_topic``: a PoseStamped topic
    of the desired (virtual) rod tip, for replay (its velocity by differentiation)."""
    try:
        from rosbags.highlevel import AnyReader
    except ImportError:
        raise RecordingError(f"{path}: reading a ROS 2 bag needs the rosbags package (pip install rosbags)") from None
    try:
        reader_cm = AnyReader([path])
        reader = reader_cm.__enter__()
    except Exception as exc:  # rosbags raises its own error types
        raise RecordingError(f"{path}: unreadable ROS 2 bag ({' '.join(str(exc).split())})") from None
    try:
        topics = {c.topic: c.msgtype for c in reader.connections}

        def series(topic: str, get: Any) -> tuple[list[int], list[list[float]]]:
            conns = [c for c in reader.connections if c.topic == topic]
            times, rows = [], []
            for conn, stamp, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                times.append(_stamp(msg, stamp))
                rows.append(get(msg))
            return times, rows

        return _frame_from_topics(path, topics, series, wrench_topic, pose_topic, twist_topic, desired_pose_topic)
    finally:
        reader_cm.__exit__(None, None, None)


def _read_mcap(path: Path, wrench_topic: str | None, pose_topic: str | None, twist_topic: str | None,
               desired_pose_topic: str | None, desired: bool) -> tuple[pd.DataFrame, str | None]:
    """An MCAP file: the project's own recording (``--mcap``: its topics by default, and the
    resolved scenario from its ``hilcontact`` metadata) or a ROS 2 bag in MCAP (ros2msg
    schemas, CDR), decoded with ``mcap-ros2-support``. Returns the columns and the scenario
    (JSON) the file carries, if any. ``desired``: read the desired tip too (replay)."""
    try:
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory
    except ImportError:
        raise RecordingError(f"{path}: reading MCAP needs the mcap and mcap-ros2-support packages") from None
    messages: dict[str, list[tuple[int, Any]]] = {}
    topics: dict[str, str] = {}
    scenario_json: str | None = None
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            if summary is not None:
                for channel in summary.channels.values():
                    schema = summary.schemas.get(channel.schema_id)
                    topics[channel.topic] = schema.name if schema is not None else ""
            for meta in reader.iter_metadata():
                if meta.name == "hilcontact" and "scenario_json" in meta.metadata:
                    scenario_json = meta.metadata["scenario_json"]
            for schema, channel, message, decoded in reader.iter_decoded_messages():
                if schema is None or "Stamped" not in schema.name:
                    continue
                topics.setdefault(channel.topic, schema.name)
                messages.setdefault(channel.topic, []).append((message.log_time, decoded))
    except RecordingError:
        raise
    except Exception as exc:  # mcap raises its own error types
        raise RecordingError(f"{path}: unreadable MCAP file ({' '.join(str(exc).split())})") from None
    own = OWN_MCAP_TOPICS["wrench"] in topics and OWN_MCAP_TOPICS["pose"] in topics
    desired_twist = None
    if own:
        wrench_topic = wrench_topic or OWN_MCAP_TOPICS["wrench"]
        pose_topic = pose_topic or OWN_MCAP_TOPICS["pose"]
        twist_topic = twist_topic or OWN_MCAP_TOPICS["twist"]
        if desired:
            desired_pose_topic = desired_pose_topic or OWN_MCAP_TOPICS["desired_pose"]
            desired_twist = OWN_MCAP_TOPICS["desired_twist"]

    def series(topic: str, get: Any) -> tuple[list[int], list[list[float]]]:
        items = messages.get(topic, [])
        return [_stamp(m, t) for t, m in items], [get(m) for _, m in items]

    frame = _frame_from_topics(path, topics, series, wrench_topic, pose_topic, twist_topic, desired_pose_topic,
                               desired_twist)
    return frame, (scenario_json if own else None)


# ---- --columns: a lab's own names, signs and units -----------------------------------------------

#: Short names of ``--columns`` keys and the canonical column each stands for.
SHORT_NAMES: dict[str, str] = {
    "t": "time",
    **{f"f{a}": f"measured_force_{a}" for a in _AXES},
    **{f"m{a}": f"measured_moment_{a}" for a in _AXES},
    **{f"p{a}": f"actual_tip_position_{a}" for a in _AXES},
    **{f"v{a}": f"actual_tip_velocity_{a}" for a in _AXES},
    **{f"dp{a}": f"tip_position_{a}" for a in _AXES},
    **{f"dv{a}": f"tip_velocity_{a}" for a in _AXES},
}
#: The units ``--columns`` accepts per quantity, and their factor to SI.
UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9},
    "force": {"N": 1.0, "kN": 1e3, "mN": 1e-3},
    "moment": {"Nm": 1.0, "N*m": 1.0, "N.m": 1.0, "Nmm": 1e-3, "N*mm": 1e-3, "N.mm": 1e-3, "kNm": 1e3},
    "position": {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "in": 0.0254},
    "velocity": {"m/s": 1.0, "cm/s": 1e-2, "mm/s": 1e-3, "um/s": 1e-6, "in/s": 0.0254},
}


def _quantity(column: str) -> str:
    if column == "time":
        return "time"
    if "force" in column:
        return "force"
    if "moment" in column:
        return "moment"
    return "velocity" if "velocity" in column else "position"


def parse_columns(spec: str | None) -> dict[str, tuple[str, float, str]]:
    """``--columns``: comma-separated ``KEY=[-]SOURCE[:UNIT]``; KEY a short name (``t``,
    ``fx``.. force, ``mx``.. moment, ``px``.. position, ``vx``.. velocity, ``dpx``/``dvx``..
    the desired tip) or a canonical column name; ``-`` flips the sign; UNIT one of
    :data:`UNITS` for the quantity (default SI). Returns canonical name -> (source, sign,
    unit). Raises :class:`RecordingError` naming the bad item."""
    mapping: dict[str, tuple[str, float, str]] = {}
    if not spec:
        return mapping
    canonical = set(SHORT_NAMES.values())
    for item in (i.strip() for i in spec.split(",")):
        if not item:
            continue
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        name = SHORT_NAMES.get(key, key)
        if not sep or not value:
            raise RecordingError(f"--columns {item!r}: expected KEY=[-]SOURCE[:UNIT], e.g. fz=-Fz or px=x_mm:mm")
        if name not in canonical:
            raise RecordingError(f"--columns {item!r}: unknown key {key!r} (t, fx/fy/fz, mx/my/mz, px/py/pz, vx/vy/vz, "
                                 "dpx.., dvx.., or a column name such as measured_force_x)")
        sign = 1.0
        if value.startswith("-"):
            sign, value = -1.0, value[1:].strip()
        quantity = _quantity(name)
        source, unit = value, next(iter(UNITS[quantity]))
        if ":" in value:
            source, _, unit = value.rpartition(":")
            if unit not in UNITS[quantity]:
                raise RecordingError(f"--columns {item!r}: unit {unit!r} is not a {quantity} unit "
                                     f"({', '.join(UNITS[quantity])})")
        if not source:
            raise RecordingError(f"--columns {item!r}: no source column")
        mapping[name] = (source, sign, unit)
    return mapping


def _apply_columns(path: Path, data: pd.DataFrame, mapping: dict[str, tuple[str, float, str]]) -> pd.DataFrame:
    """``data`` with the mapped canonical columns (sign and unit applied, in SI) replacing or
    adding to its own."""
    if not mapping:
        return data
    out = data.copy()
    for name, (source, sign, unit) in mapping.items():
        if source not in data.columns:
            raise RecordingError(f"{path}: --columns {name}: no column {source!r}; columns: {', '.join(map(str, data.columns))}")
        values = pd.to_numeric(data[source], errors="coerce").to_numpy(dtype=np.float64)
        out[name] = sign * UNITS[_quantity(name)][unit] * values
    return out


def _complete(path: Path, data: pd.DataFrame, need: list[str], derived: list[str]) -> pd.DataFrame:
    """Fills what identification can do without: velocities (differentiated from the
    positions) and moments (zero) when all three are missing, noting it in ``derived``."""
    identify_only = not any(c in need for c in DESIRED_COLUMNS)
    velocity, position = _vec("actual_tip_velocity"), _vec("actual_tip_position")
    if all(c not in data.columns for c in velocity) and all(c in data.columns for c in position) \
            and "time" in data.columns:
        t = data["time"].to_numpy(dtype=np.float64)
        if len(t) >= 2 and np.all(np.diff(t) > 0):
            data = data.copy()
            v = differentiate(t, data[position].to_numpy(dtype=np.float64))
            for i, c in enumerate(velocity):
                data[c] = v[:, i]
            derived.append("actual_tip_velocity_*: differentiated from the position (central differences)")
    moment = _vec("measured_moment")
    if identify_only and all(c not in data.columns for c in moment):
        data = data.copy()
        for c in moment:
            data[c] = 0.0
        derived.append("measured_moment_*: not in the recording, taken as zero (identification does not use them)")
    return data


def read_recording(log: str | os.PathLike[str], scenario: str | None = None,
                   overrides: dict[str, Any] | None = None, wrench_topic: str | None = None,
                   pose_topic: str | None = None, twist_topic: str | None = None,
                   need: list[str] | None = None, desired_pose_topic: str | None = None,
                   columns: str | dict[str, tuple[str, float, str]] | None = None) -> Recording:
    """Read a recording: a run folder, a ``.csv`` or ``.parquet`` file, a ROS 2 bag folder
    (with ``metadata.yaml``), or an ``.mcap`` file (the project's own ``--mcap`` recording or
    a ROS 2 bag in MCAP). ``scenario`` (preset or TOML) gives the geometry and the compensator
    (a run folder's own ``scenario.toml`` or an own MCAP's scenario by default, else
    :data:`DEFAULT_SCENARIO`); ``overrides`` are ``--set`` keys. ``columns``: the
    ``--columns`` mapping (:func:`parse_columns`). ``need``: columns that must be present
    (named if missing; velocities and, for identification, moments may be derived, see
    :func:`_complete`). Raises :class:`RecordingError` or ScenarioError."""
    path = Path(log)
    mapping = parse_columns(columns) if isinstance(columns, str) or columns is None else dict(columns)
    need = need or IDENTIFY_COLUMNS
    own_scenario: Any = None
    if path.is_dir() and (path / "timeseries.parquet").is_file():
        data = _read_table(path / "timeseries.parquet")
        if (path / "scenario.toml").is_file():
            own_scenario = path / "scenario.toml"
    elif path.is_dir() and (path / "metadata.yaml").is_file():
        data = _read_bag(path, wrench_topic, pose_topic, twist_topic, desired_pose_topic)
    elif path.is_file() and path.suffix.lower() == ".mcap":
        desired = any(c in need for c in DESIRED_COLUMNS)
        data, carried = _read_mcap(path, wrench_topic, pose_topic, twist_topic, desired_pose_topic, desired)
        if carried is not None:
            own_scenario = json.loads(carried)
    elif path.is_file() and path.suffix.lower() in (".csv", ".parquet", ".pq"):
        data = _read_table(path)
    elif not path.exists():
        raise RecordingError(f"{path}: no such file or folder")
    else:
        raise RecordingError(
            f"{path}: not a recording (expected a run folder, a .csv, .parquet or .mcap file, or a ROS 2 bag folder "
            "with metadata.yaml)")
    data = _apply_columns(path, data, mapping)
    derived: list[str] = []
    data = _complete(path, data, need, derived)
    missing = [c for c in need if c not in data.columns]
    if missing:
        raise RecordingError(f"{path}: missing columns: {', '.join(missing)}")
    _check_time_unit(path, data, mapping)
    source: Any = scenario if scenario is not None else (own_scenario if own_scenario is not None else DEFAULT_SCENARIO)
    overrides = dict(overrides or {})
    if own_scenario is None or scenario is not None:
        t = data["time"].to_numpy(dtype=np.float64)
        steps = np.diff(t)
        if len(steps) and np.all(np.isfinite(steps)) and np.all(steps > 0):
            period = float(np.median(steps))
            base = load_scenario(source, overrides)
            if "simulation.period" not in overrides and not math.isclose(period, base.simulation.period, rel_tol=1e-6):
                overrides["simulation.period"] = round(period, 9)
    return Recording(source=str(path), data=data, scenario=load_scenario(source, overrides), derived=derived,
                     mapping=mapping)


#: Longest and shortest plausible control period of a recording, s (a time column in ms or
#: µs read as s falls outside).
PERIOD_RANGE = (1e-5, 0.05)


def _check_time_unit(path: Path, data: pd.DataFrame, mapping: dict[str, tuple[str, float, str]]) -> None:
    """Refuses a recording whose median time step is outside :data:`PERIOD_RANGE` (a time in
    ms or ns read as s), naming the likely unit."""
    t = data["time"].to_numpy(dtype=np.float64)
    steps = np.diff(t)
    steps = steps[np.isfinite(steps) & (steps > 0)]
    if len(steps) == 0:
        return
    step = float(np.median(steps))
    source = mapping.get("time", ("time", 1.0, "s"))[0]
    if step > PERIOD_RANGE[1]:
        unit = "ms" if step < 50 else "us"
        raise RecordingError(f"{path}: time steps of {step:g} s (a {1 / step:.3g} Hz loop): is time in {unit}? "
                             f"(--columns t={source}:{unit})")
    if step < PERIOD_RANGE[0]:
        unit = "us" if step > 1e-8 else "ns"
        raise RecordingError(f"{path}: time steps of {step:g} s: is time in {unit}? (--columns t={source}:{unit})")


def _call(recording: Recording, name: str, scenario: Scenario, columns: list[str]) -> Any:
    try:
        return getattr(_core(), name)(scenario.to_json(), recording.columns(columns))
    except ScenarioError as exc:
        message = str(exc)
        if message.startswith("recording: "):
            raise RecordingError(f"{recording.source}: {message[len('recording: '):]}") from None
        raise


def replay(recording: Recording) -> pd.DataFrame:
    """The recording's compensator (its scenario's ``[compensator]``) run on its
    measurements and poses: one row per tick with time, applied_force_*, applied_moment_*
    (sensor frame), velocity_correction_*, stiffness_estimate, damping_estimate,
    observed_energy."""
    missing = [c for c in IDENTIFY_COLUMNS + DESIRED_COLUMNS if c not in recording.data.columns]
    if missing:
        raise RecordingError(f"{recording.source}: missing columns: {', '.join(missing)}")
    out = _call(recording, "replay", recording.scenario, IDENTIFY_COLUMNS + DESIRED_COLUMNS)
    return pd.DataFrame({k: np.asarray(v, dtype=np.float64) for k, v in out.items()})


def identification_scenario(scenario: Scenario, forgetting: float | None = OFFLINE_FORGETTING) -> Scenario:
    """The scenario whose compensator identifies: its own if pic, dac or pida, else pida with
    defaults; the noise estimate's forgetting factor set to ``forgetting`` (None: keep)."""
    data = scenario.to_dict()
    comp = data.get("compensator") or {}
    if comp.get("kind") not in ("pic", "dac", "pida"):
        comp = {"kind": "pida"}
    if forgetting is not None:
        comp["forgetting"] = forgetting
    data["compensator"] = comp
    return load_scenario(data)


def _fresh_rows(recording: Recording) -> np.ndarray | None:
    """A real-time run's ticks that had a new sensor record (its ``sensor_age`` column, the
    time since the record in use arrived, is 0), or None when every tick had one or the
    recording has no such column."""
    if "sensor_age" not in recording.data.columns:
        return None
    fresh = recording.data["sensor_age"].to_numpy(dtype=np.float64) <= 0
    fresh[0] = True
    return None if fresh.all() else fresh


def _fresh_recording(recording: Recording, scenario: Scenario,
                     fresh: np.ndarray) -> tuple[Recording, Scenario, np.ndarray]:
    """A real-time run's ticks without a new sensor record held the last force while the
    kinematics moved on: the recording of the ticks with a new record only, each with the
    kinematics that produced it (τ_p earlier for align, taken here, so the returned scenario's
    sensor delay is 0; the increments then span the held ticks), and the rows kept."""
    data = recording.data
    kept_rows = np.flatnonzero(fresh)
    lag = alignment_lag(scenario)
    kept = data.iloc[kept_rows].reset_index(drop=True)
    for name in (*_vec("actual_tip_position"), *_vec("actual_tip_velocity")):
        kept[name] = data[name].to_numpy(dtype=np.float64)[np.maximum(kept_rows - lag, 0)]
    shifted = scenario.to_dict()
    if lag:
        shifted["facility"]["sensor_delay"] = 0.0
    note = (f"sensor_age: identified on the {len(kept_rows)} ticks with a new sensor record "
            f"({len(data) - len(kept_rows)} held the previous one)")
    if note not in recording.derived:
        recording.derived.append(note)
    sub = Recording(source=recording.source, data=kept, scenario=recording.scenario)
    return sub, load_scenario(shifted), kept_rows


#: A real-time run's column: the age of the robot feedback in use, s.
ROBOT_AGE = "robot_age"


def online_identification(recording: Recording) -> dict[str, Any] | None:
    """The live loop's own k̂, ĉ at the end of a run and their standard deviations
    (``{stiffness, stiffness_std (N/m), damping, damping_std (N s/m), updates, contacts}``,
    None before any update): the scenario compensator's front end replayed over the recording
    as the loop runs it (one filter, never restarted, its own forgetting), its uncertainty from
    its gains and residuals (``identify.rs`` ``online_identification``). A real-time run's held
    records are left out as :func:`identify` leaves them (the loop learns only from new ones),
    and its ``robot_age`` adds the pairing's timing to ĉ's: ``timing`` (s), the RMS age of the
    robot feedback, times k̂ (docs/identification.md)."""
    scenario = identification_scenario(recording.scenario, None)
    fresh = _fresh_rows(recording)
    if fresh is None:
        out = _call(recording, "online_identification", scenario, IDENTIFY_COLUMNS)
    else:
        sub, shifted, _ = _fresh_recording(recording, scenario, fresh)
        out = _call(sub, "online_identification", shifted, IDENTIFY_COLUMNS)
    if out is not None and ROBOT_AGE in recording.data.columns:
        # the kinematics a force is paired with are known to within their feedback's age: a
        # timing error δ shifts ĉ by −k·δ (F(t − δ) = k·d + (c − k·δ)·ḋ + …), stated as k̂·δ_rms
        age = recording.data[ROBOT_AGE].to_numpy(dtype=np.float64)
        out["timing"] = float(np.sqrt(np.mean(age[np.isfinite(age)] ** 2))) if np.isfinite(age).any() else 0.0
        out["damping_std"] = float(np.hypot(out["damping_std"], abs(out["stiffness"]) * out["timing"]))
    return out


def identify(recording: Recording, forgetting: float | None = OFFLINE_FORGETTING) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per tick (time, in_contact, stiffness/damping estimate and std) and per collision
    (index, start, end, samples, updates, stiffness, stiffness_std (N/m), damping,
    damping_std (N s/m), normal_x.. (unit, ``t``), normal_std_deg, point_x.. (m, ``t``),
    offset_std (m), peak_force (N), frictional, friction (μ̂), friction_std, sliding_samples)."""
    scenario = identification_scenario(recording.scenario, forgetting)
    fresh = _fresh_rows(recording)
    if fresh is None:
        out = _call(recording, "identify", scenario, IDENTIFY_COLUMNS)
        ticks = pd.DataFrame({k: np.asarray(v, dtype=np.float64) for k, v in out["timeseries"].items()})
    else:
        data = recording.data
        sub, shifted, kept_rows = _fresh_recording(recording, scenario, fresh)
        out = _call(sub, "identify", shifted, IDENTIFY_COLUMNS)
        part = pd.DataFrame({k: np.asarray(v, dtype=np.float64) for k, v in out["timeseries"].items()})
        # back on every tick: a held tick shows the estimate of its record's tick
        source = np.maximum.accumulate(np.where(fresh, np.arange(len(data)), 0))
        ticks = part.iloc[np.searchsorted(kept_rows, source)].reset_index(drop=True)
        ticks["time"] = data["time"].to_numpy(dtype=np.float64)
    rows = []
    for c in out["collisions"]:
        row = {k: c[k] for k in ("index", "start", "end", "samples", "updates", "stiffness", "stiffness_std",
                                   "damping", "damping_std")}
        row.update({f"normal_{a}": c["normal"][i] for i, a in enumerate(_AXES)})
        row["normal_std_deg"] = math.degrees(c["normal_std"])
        row.update({f"point_{a}": c["point"][i] for i, a in enumerate(_AXES)})
        row["offset_std"] = c["offset_std"]
        row["peak_force"] = c["peak_force"]
        for k in ("frictional", "friction", "friction_std", "sliding_samples"):
            if k in c:
                row[k] = c[k]
        rows.append(row)
    return ticks, pd.DataFrame(rows)


# ---- plausibility of an identification -----------------------------------------------------------

#: Softest and stiffest contact taken as plausible, N/m (1 N/mm to 100 kN/mm): a docking
#: contact of a facility with masses of hundreds of kg; a position in mm read as m gives a
#: stiffness 1000 times too low, one in m declared as mm 1000 times too high.
STIFFNESS_RANGE = (1e3, 1e8)
#: Farthest the identified wall may lie from the tip at a collision's first contact sample, m
#: (at the contact threshold the penetration is a few µm at plausible stiffnesses).
WALL_DISTANCE = 0.02
#: Farthest from the frame's origin a rod tip is taken as plausible, m (positions in mm read
#: as m put it kilometres away).
POSITION_RANGE = 5.0
#: Below this correlation of the force with the penetration over a collision, the force is
#: taken as not rising with it; below its negative, as anticorrelated.
CORRELATION = 0.5


@dataclass(frozen=True)
class Finding:
    """One plausibility check that failed: ``error`` refuses (exit 2), ``warning`` is
    printed. ``message``: one line, the likely cause and the fix."""

    level: str
    message: str


def _source(recording: Recording, name: str) -> str:
    """The recording's own column name behind canonical ``name`` (for a ``--columns`` hint)."""
    return recording.mapping.get(name, (name, 1.0, ""))[0]


def _penetration_correlations(recording: Recording, ticks: pd.DataFrame, collisions: pd.DataFrame,
                              lag: int) -> list[float]:
    """Per collision: the correlation of the force magnitude with the penetration ``p·ē``
    (``ē = −n``, the direction of the summed force; the tip ``lag`` ticks earlier, the
    kinematics that produced the force)."""
    data = recording.data
    time = data["time"].to_numpy(dtype=np.float64)
    force = np.linalg.norm(data[_vec("measured_force")].to_numpy(dtype=np.float64), axis=1)
    position = data[_vec("actual_tip_position")].to_numpy(dtype=np.float64)
    out = []
    for _, c in collisions.iterrows():
        first = int(np.searchsorted(time, c["start"]))
        last = int(np.searchsorted(time, c["end"]))
        if last - first < 3:
            continue
        k = np.arange(first, last + 1)
        e = -np.array([c["normal_x"], c["normal_y"], c["normal_z"]])
        d = position[np.maximum(k - lag, 0)] @ e
        f = force[k]
        if np.std(d) <= 0 or np.std(f) <= 0:
            out.append(0.0)
            continue
        out.append(float(np.corrcoef(d, f)[0, 1]))
    return out


def check_plausibility(recording: Recording, ticks: pd.DataFrame, collisions: pd.DataFrame) -> list[Finding]:
    """The plausibility checks of an identification (docs/identification.md): no collision,
    a force and penetration anticorrelated (force's sign flipped) or uncorrelated, a
    stiffness negative or outside :data:`STIFFNESS_RANGE` (units), positions beyond
    :data:`POSITION_RANGE` (mm read as m), a velocity that is not the position's derivative
    (sign or unit), a wall farther than :data:`WALL_DISTANCE` from the tip at first contact.
    Errors where the cause is clear, warnings where it is ambiguous."""
    findings: list[Finding] = []
    data = recording.data
    error = lambda m: findings.append(Finding("error", m))  # noqa: E731
    warn = lambda m: findings.append(Finding("warning", m))  # noqa: E731
    position = data[_vec("actual_tip_position")].to_numpy(dtype=np.float64)
    force = data[_vec("measured_force")].to_numpy(dtype=np.float64)
    axis = int(np.argmax(np.max(np.abs(force), axis=0)))
    f_name = f"f{_AXES[axis]}"
    f_source = _source(recording, f"measured_force_{_AXES[axis]}")
    p_hint = "--columns " + ",".join(f"p{a}={_source(recording, f'actual_tip_position_{a}')}:mm" for a in _AXES)
    if not any(d.startswith("actual_tip_velocity") for d in recording.derived):
        p_hint += "".join(f",v{a}={_source(recording, f'actual_tip_velocity_{a}')}:mm/s" for a in _AXES)
    far = float(np.max(np.abs(position)))

    # the velocity against the position's derivative (when it was read, not derived)
    if not any(d.startswith("actual_tip_velocity") for d in recording.derived):
        t = data["time"].to_numpy(dtype=np.float64)
        velocity = data[_vec("actual_tip_velocity")].to_numpy(dtype=np.float64)
        derivative = differentiate(t, position)
        window = max(1, min(len(t) // 10, 21))
        kernel = np.ones(window) / window
        i = int(np.argmax(np.std(derivative, axis=0)))
        a = np.convolve(derivative[:, i], kernel, mode="valid")
        b = np.convolve(velocity[:, i], kernel, mode="valid")
        if np.std(a) > 1e-6 and np.std(b) > 0:
            ratio = float(np.dot(a - a.mean(), b - b.mean()) / np.dot(a - a.mean(), a - a.mean()))
            v_source = _source(recording, f"actual_tip_velocity_{_AXES[i]}")
            if ratio < 0:
                error(f"the velocity and the position's derivative have opposite signs (ratio {ratio:.3g}): "
                      f"is the velocity's sign flipped? (--columns v{_AXES[i]}=-{v_source})")
            elif not 0.2 <= ratio <= 5.0:
                unit = "mm/s" if ratio > 5.0 else "m/s"
                error(f"the velocity is {ratio:.3g} times the position's derivative: are they in different units? "
                      f"(e.g. --columns v{_AXES[i]}={v_source}:{unit}, or the position's unit)")

    if len(collisions) == 0:
        comp = identification_scenario(recording.scenario, None).to_dict().get("compensator") or {}
        threshold = float(comp.get("contact_force", 3.0))
        peak = float(np.max(np.linalg.norm(force, axis=1)))
        warn(f"no collision found: the largest force is {peak:.3g} N (contact threshold {threshold:g} N)"
             + (f": is the force in kN? (--columns {f_name}={f_source}:kN)" if peak < threshold else ""))
        return findings

    lag = alignment_lag(recording.scenario)
    r = _penetration_correlations(recording, ticks, collisions, lag)
    k = collisions["stiffness"].to_numpy(dtype=np.float64)
    k_typical = float(np.median(k))
    r_typical = float(np.median(r)) if r else 0.0
    if r and r_typical <= -CORRELATION:
        error(f"force and penetration are anticorrelated (r = {r_typical:.2f}, k = {k_typical / 1e3:.4g} N/mm): "
              f"is the force's sign flipped? (--columns {f_name}=-{f_source})")
    elif k_typical <= 0:
        error(f"negative stiffness k = {k_typical / 1e3:.4g} N/mm: is the force's or the position's sign flipped? "
              f"(--columns {f_name}=-{f_source})")
    elif k_typical < STIFFNESS_RANGE[0]:
        message = (f"stiffness k = {k_typical / 1e3:.4g} N/mm is implausibly low (< {STIFFNESS_RANGE[0] / 1e3:g} N/mm)")
        if far > POSITION_RANGE or far > 0.2:
            error(f"{message} and the tip is up to {far:.4g} m from the origin: are the positions in mm? ({p_hint})")
        else:
            warn(f"{message}: are the positions in mm ({p_hint}) or the force in mN?")
    elif k_typical > STIFFNESS_RANGE[1]:
        warn(f"stiffness k = {k_typical / 1e3:.4g} N/mm is implausibly high (> {STIFFNESS_RANGE[1] / 1e3:g} N/mm): "
             "a position declared in mm that is in m, or a force in the wrong unit?")
    elif far > POSITION_RANGE:
        warn(f"the tip is up to {far:.4g} m from the origin of t: are the positions in mm? ({p_hint})")
    if r and -CORRELATION < r_typical < CORRELATION:
        warn(f"the force hardly rises with the penetration (median correlation {r_typical:.2f} over "
             f"{len(r)} collisions): forces and poses from different times, or the tip not where the contact is?")
    if not any(f.level == "error" for f in findings):
        for _, c in collisions.iterrows():
            first = int(np.searchsorted(data["time"].to_numpy(dtype=np.float64), c["start"]))
            n = np.array([c["normal_x"], c["normal_y"], c["normal_z"]])
            point = np.array([c["point_x"], c["point_y"], c["point_z"]])
            # the plane's offset from the first contact's tip (the reported point is on the plane)
            offsets = (position[max(first - lag, 0):] - point) @ n
            distance = float(abs(offsets[0])) if len(offsets) else 0.0
            if distance > WALL_DISTANCE or not np.isfinite(distance):
                warn(f"collision {int(c['index'])}: the identified wall is {distance * 1e3:.4g} mm from the tip at its "
                     f"first contact: the stiffness, or the force's or the positions' unit, is off")
                break
    return findings


def save_replay(recording: Recording, table: pd.DataFrame, out: str | os.PathLike[str], force: bool = False) -> dict[str, Any]:
    """Write replay.parquet, summary.json and scenario.toml into ``out`` (atomically);
    returns the summary (with the largest relative difference to the recorded applied wrench
    when the recording has it)."""
    summary: dict[str, Any] = {"source": recording.source, "compensator": recording.scenario.python_entry or recording.scenario.compensator.kind,
                               "samples": len(table)}
    names = [*_vec("applied_force"), *_vec("applied_moment")]
    if all(n in recording.data.columns for n in names):
        recorded = recording.data[names].to_numpy(dtype=np.float64)
        replayed = table[names].to_numpy(dtype=np.float64)
        scale = max(float(np.max(np.abs(recorded))), 1e-12)
        summary["max_relative_difference_to_recorded"] = float(np.max(np.abs(replayed - recorded))) / scale

    def write(folder: Path) -> None:
        table.to_parquet(folder / "replay.parquet", engine="pyarrow", index=False)
        (folder / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
        (folder / "scenario.toml").write_text(recording.scenario.to_toml(), encoding="utf-8")

    write_atomically(out, write, "replay", force)
    return summary


def alignment_lag(scenario: Scenario) -> int:
    """Ticks between a force sample and the kinematics that produced it in identification:
    ``τ_p/T`` for ``align``, 0 for ``lead`` (the front end's own rule)."""
    data = scenario.to_dict()
    comp = identification_scenario(scenario, None).to_dict().get("compensator") or {}
    if comp.get("delay_mode", "align") == "lead":
        return 0
    period = float(data["simulation"]["period"])
    return int(round(float((data.get("facility") or {}).get("sensor_delay", 0.0)) / period))


def save_identification(recording: Recording, ticks: pd.DataFrame, collisions: pd.DataFrame,
                        out: str | os.PathLike[str], force: bool = False, plots: bool = True) -> None:
    """Write identification.parquet (per tick), collisions.csv, collisions.json,
    scenario.toml and (``plots``) identification.png and force_penetration.png."""
    def write(folder: Path) -> None:
        ticks.to_parquet(folder / "identification.parquet", engine="pyarrow", index=False)
        collisions.to_csv(folder / "collisions.csv", index=False)
        (folder / "collisions.json").write_text(
            json.dumps({"source": recording.source, "derived": recording.derived,
                        "collisions": collisions.to_dict(orient="records")}, indent=2) + "\n",
            encoding="utf-8")
        (folder / "scenario.toml").write_text(recording.scenario.to_toml(), encoding="utf-8")
        if plots:
            from .identification_plots import save_identification_figures

            save_identification_figures(recording.data, ticks, collisions, alignment_lag(recording.scenario),
                                        Path(recording.source).name, folder)

    write_atomically(out, write, "identification", force)
