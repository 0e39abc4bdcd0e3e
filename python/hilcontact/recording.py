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
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
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
    "identify", "read_recording", "replay",
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


def _read_bag(path: Path, wrench_topic: str | None, pose_topic: str | None,
              twist_topic: str | None, desired_pose_topic: str | None = None) -> pd.DataFrame:
    """A ROS 2 bag's WrenchStamped and PoseStamped (and TwistStamped) topics, on the wrench's
    time base (pose linearly interpolated, velocity by differentiation if no twist topic);
    ``desired_pose_topic``: a PoseStamped topic of the desired (virtual) rod tip, for replay
    (its velocity by differentiation)."""
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

        def pick(topic: str | None, kind: str, option: str) -> str | None:
            if topic is not None:
                if topic not in topics:
                    raise RecordingError(f"{path}: no topic {topic} ({option}); topics: {', '.join(sorted(topics)) or '(none)'}")
                return topic
            found = sorted(t for t, m in topics.items() if m.endswith(kind))
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

        def series(topic: str, get: Any) -> tuple[np.ndarray, np.ndarray]:
            conns = [c for c in reader.connections if c.topic == topic]
            times, rows = [], []
            for conn, stamp, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                times.append(_stamp(msg, stamp))
                rows.append(get(msg))
            if not rows:
                raise RecordingError(f"{path}: topic {topic} has no messages")
            return np.asarray(times, dtype=np.int64), np.asarray(rows, dtype=np.float64)

        tw, w = series(wrench, lambda m: [m.wrench.force.x, m.wrench.force.y, m.wrench.force.z,
                                          m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z])
        tp, p = series(pose, lambda m: [m.pose.position.x, m.pose.position.y, m.pose.position.z])
        if twist is not None:
            tv, v = series(twist, lambda m: [m.twist.linear.x, m.twist.linear.y, m.twist.linear.z])
        else:
            if len(tp) < 2:
                raise RecordingError(f"{path}: topic {pose} has fewer than 2 messages")
            tv, v = tp, None
        if desired is not None:
            td, d = series(desired, lambda m: [m.pose.position.x, m.pose.position.y, m.pose.position.z])
            if len(td) < 2:
                raise RecordingError(f"{path}: topic {desired} has fewer than 2 messages")
    finally:
        reader_cm.__exit__(None, None, None)
    # seconds from the first wrench, exact in integer ns before the conversion
    start = tw[0]
    tw, tp, tv = ((t - start).astype(np.float64) * 1e-9 for t in (tw, tp, tv))
    if v is None:  # no twist topic: differentiate the pose
        v = np.stack([np.gradient(p[:, i], tp) for i in range(3)], axis=1)
    if desired is not None:
        td = (td - start).astype(np.float64) * 1e-9
        dv = np.stack([np.gradient(d[:, i], td) for i in range(3)], axis=1)
    for name, t in ((wrench, tw), (pose, tp)):
        if np.any(np.diff(t) <= 0):
            i = int(np.argmax(np.diff(t) <= 0)) + 1
            raise RecordingError(f"{path}: topic {name}: time is not strictly increasing at message {i}")
    data: dict[str, np.ndarray] = {"time": tw}
    for i, a in enumerate(_AXES):
        data[f"measured_force_{a}"] = w[:, i]
        data[f"measured_moment_{a}"] = w[:, 3 + i]
        data[f"actual_tip_position_{a}"] = np.interp(tw, tp, p[:, i])
        data[f"actual_tip_velocity_{a}"] = np.interp(tw, tv, v[:, i])
        if desired is not None:
            data[f"tip_position_{a}"] = np.interp(tw, td, d[:, i])
            data[f"tip_velocity_{a}"] = np.interp(tw, td, dv[:, i])
    return pd.DataFrame(data)


def read_recording(log: str | os.PathLike[str], scenario: str | None = None,
                   overrides: dict[str, Any] | None = None, wrench_topic: str | None = None,
                   pose_topic: str | None = None, twist_topic: str | None = None,
                   need: list[str] | None = None, desired_pose_topic: str | None = None) -> Recording:
    """Read a recording: a run folder, a ``.csv`` or ``.parquet`` file, or a ROS 2 bag folder
    (with ``metadata.yaml``). ``scenario`` (preset or TOML) gives the geometry and the
    compensator (a run folder's own ``scenario.toml`` by default, else :data:`DEFAULT_SCENARIO`);
    ``overrides`` are ``--set`` keys. ``need``: columns that must be present (named if
    missing). Raises :class:`RecordingError` or ScenarioError."""
    path = Path(log)
    own_scenario: Path | None = None
    if path.is_dir() and (path / "timeseries.parquet").is_file():
        data = _read_table(path / "timeseries.parquet")
        if (path / "scenario.toml").is_file():
            own_scenario = path / "scenario.toml"
    elif path.is_dir() and (path / "metadata.yaml").is_file():
        data = _read_bag(path, wrench_topic, pose_topic, twist_topic, desired_pose_topic)
    elif path.is_file() and path.suffix.lower() in (".csv", ".parquet", ".pq"):
        data = _read_table(path)
    elif not path.exists():
        raise RecordingError(f"{path}: no such file or folder")
    else:
        raise RecordingError(
            f"{path}: not a recording (expected a run folder, a .csv or .parquet file, or a ROS 2 bag folder with metadata.yaml)")
    missing = [c for c in (need or IDENTIFY_COLUMNS) if c not in data.columns]
    if missing:
        raise RecordingError(f"{path}: missing columns: {', '.join(missing)}")
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
    return Recording(source=str(path), data=data, scenario=load_scenario(source, overrides))


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


def identify(recording: Recording, forgetting: float | None = OFFLINE_FORGETTING) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per tick (time, in_contact, stiffness/damping estimate and std) and per collision
    (index, start, end, samples, updates, stiffness, stiffness_std (N/m), damping,
    damping_std (N s/m), normal_x.. (unit, ``t``), normal_std_deg, point_x.. (m, ``t``),
    offset_std (m), peak_force (N))."""
    scenario = identification_scenario(recording.scenario, forgetting)
    out = _call(recording, "identify", scenario, IDENTIFY_COLUMNS)
    ticks = pd.DataFrame({k: np.asarray(v, dtype=np.float64) for k, v in out["timeseries"].items()})
    rows = []
    for c in out["collisions"]:
        row = {k: c[k] for k in ("index", "start", "end", "samples", "updates", "stiffness", "stiffness_std",
                                   "damping", "damping_std")}
        row.update({f"normal_{a}": c["normal"][i] for i, a in enumerate(_AXES)})
        row["normal_std_deg"] = math.degrees(c["normal_std"])
        row.update({f"point_{a}": c["point"][i] for i, a in enumerate(_AXES)})
        row["offset_std"] = c["offset_std"]
        row["peak_force"] = c["peak_force"]
        rows.append(row)
    return ticks, pd.DataFrame(rows)


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


def save_identification(recording: Recording, ticks: pd.DataFrame, collisions: pd.DataFrame,
                        out: str | os.PathLike[str], force: bool = False) -> None:
    """Write identification.parquet (per tick), collisions.csv and collisions.json."""
    def write(folder: Path) -> None:
        ticks.to_parquet(folder / "identification.parquet", engine="pyarrow", index=False)
        collisions.to_csv(folder / "collisions.csv", index=False)
        (folder / "collisions.json").write_text(
            json.dumps({"source": recording.source, "collisions": collisions.to_dict(orient="records")}, indent=2) + "\n",
            encoding="utf-8")
        (folder / "scenario.toml").write_text(recording.scenario.to_toml(), encoding="utf-8")

    write_atomically(out, write, "identification", force)
