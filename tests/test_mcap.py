"""MCAP recordings (`--mcap FILE`): read back with the Python `mcap` reader, decoded with
`mcap-ros2-support` (from the schemas in the file) and, independently, with `rosbags`' CDR
deserializer; a simulation, a real-time run across processes, and a run killed with SIGKILL."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

mcap_reader = pytest.importorskip("mcap.reader")
mcap_ros2_decoder = pytest.importorskip("mcap_ros2.decoder")
rosbags_typesys = pytest.importorskip("rosbags.typesys")

from mcap.exceptions import McapError  # noqa: E402

from test_cli import assert_one_error_line, invoke  # noqa: E402
from test_realtime_e2e import ROBOT_DELAY, facility_process, hil_command, run_hil  # noqa: E402

#: The channels written once per tick by every run (the Rust `output::mcap::CHANNELS`).
PER_TICK = [
    "/hil/measured_wrench",
    "/hil/applied_wrench",
    "/hil/contact_force",
    "/hil/tip/commanded",
    "/hil/tip/actual",
    "/hil/tip/commanded_velocity",
    "/hil/tip/actual_velocity",
    "/hil/energy",
]
SCHEMAS = {
    "/hil/measured_wrench": "geometry_msgs/msg/WrenchStamped",
    "/hil/applied_wrench": "geometry_msgs/msg/WrenchStamped",
    "/hil/contact_force": "geometry_msgs/msg/Vector3Stamped",
    "/hil/tip/commanded": "geometry_msgs/msg/PoseStamped",
    "/hil/tip/actual": "geometry_msgs/msg/PoseStamped",
    "/hil/tip/commanded_velocity": "geometry_msgs/msg/TwistStamped",
    "/hil/tip/actual_velocity": "geometry_msgs/msg/TwistStamped",
    "/hil/energy": "hilcontact_msgs/msg/Energy",
    "/hil/estimates": "hilcontact_msgs/msg/ContactEstimate",
    "/hil/loop_timing": "hilcontact_msgs/msg/LoopTiming",
    "/hil/events": "rcl_interfaces/msg/Log",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    # the facility in 3-D, as the live view draws it (the Rust `output::scene::SCENE_CHANNELS`)
    "/hil/scene": "visualization_msgs/msg/MarkerArray",
    "/tf": "tf2_msgs/msg/TFMessage",
}
#: The scene's channels, one message every SCENE_EVERY ticks (30 Hz of run time at 1 ms).
SCENE = ["/hil/scene", "/tf"]
SCENE_EVERY = 33


def scene_messages(n: int) -> int:
    """Scene messages per scene channel of a run of ``n`` ticks (ticks 0, 33, 66, ...)."""
    return (n - 1) // SCENE_EVERY + 1


def read_decoded(path: Path) -> tuple[dict[str, list], object, dict]:
    """Every message of a finished file, decoded from its own schemas (`mcap-ros2-support`),
    per topic in file order; the summary; the `hilcontact` metadata."""
    messages: dict[str, list] = defaultdict(list)
    with open(path, "rb") as f:
        reader = mcap_reader.make_reader(f, validate_crcs=True, decoder_factories=[mcap_ros2_decoder.DecoderFactory()])
        summary = reader.get_summary()
        last = -1
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            assert message.log_time >= last, "the file is in time order"
            last = message.log_time
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            assert schema.name == SCHEMAS[channel.topic], channel.topic
            messages[channel.topic].append((message, decoded))
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return messages, summary, metadata


def rosbags_store(summary) -> object:
    """A `rosbags` type store with the standard ROS 2 types and the file's own
    `hilcontact_msgs` definitions (parsed from its schemas)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    custom = {}
    for schema in summary.schemas.values():
        if schema.name.startswith("hilcontact_msgs/"):
            types = get_types_from_msg(schema.data.decode(), schema.name)
            custom[schema.name] = types[schema.name]
    store.register(custom)
    return store


def own_definitions_store(summary, name: str) -> object:
    """A `rosbags` type store with only the file's own definition of ``name`` and its
    dependencies (the scene's Marker is ROS 1/Foxy's, without Humble's texture and mesh
    fields, as its schema in the file says)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    schema = next(s for s in summary.schemas.values() if s.name == name)
    store.register(get_types_from_msg(schema.data.decode(), schema.name))
    return store


def stamp(decoded) -> int:
    """A header's stamp, ns."""
    return decoded.header.stamp.sec * 1_000_000_000 + decoded.header.stamp.nanosec


def ns(times) -> list[int]:
    """Run times (s) in ns, as the recording stamps them."""
    return [int(v) for v in np.round(np.asarray(times, dtype=float) * 1e9)]


def same(a, b) -> bool:
    """Equal as float64, NaN equal to NaN."""
    return np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float), equal_nan=True)


@pytest.mark.parametrize("compensator", ["none", "pida"])
def test_run_records_every_channel_with_the_run_s_sample_count(core, tmp_path, compensator):
    out, path = tmp_path / "run", tmp_path / "run.mcap"
    result = invoke("run", "paper-table1", "--set", f"compensator.kind={compensator}", "--out", str(out),
                    "--no-plots", "--mcap", str(path))
    assert result.exit_code == 0, result.output
    assert f"mcap: {path}" in result.stdout.replace("\n", "")
    series = pd.read_parquet(out / "timeseries.parquet")
    n = len(series)
    messages, summary, metadata = read_decoded(path)

    # every channel, with one message per tick (the estimates only for a compensator that
    # identifies the contact; no loop timing in a simulation)
    expected = {topic: n for topic in PER_TICK} | {"/hil/events": 2, "/tf_static": 1}
    expected |= {topic: scene_messages(n) for topic in SCENE}
    if compensator == "pida":
        expected["/hil/estimates"] = n
    assert {t: len(m) for t, m in messages.items()} == expected
    counts = {summary.channels[c].topic: k for c, k in summary.statistics.channel_message_counts.items()}
    assert counts == expected
    assert summary.statistics.chunk_count >= math.ceil(series["time"].iloc[-1] / 0.5)

    # decoded values equal the time series, stamps equal its time
    decoded = {topic: [d for _, d in m] for topic, m in messages.items()}
    t = ns(series["time"])
    assert t == [k * 1_000_000 for k in range(n)]
    for topic in PER_TICK:
        assert [stamp(d) for d in decoded[topic]] == t, topic
        assert [m.log_time for m, _ in messages[topic]] == t, topic
    wrench = decoded["/hil/measured_wrench"]
    for i, axis in enumerate("xyz"):
        assert same([getattr(d.wrench.force, axis) for d in wrench], series[f"measured_force_{axis}"]), axis
        assert same([getattr(d.wrench.torque, axis) for d in wrench], series[f"measured_moment_{axis}"]), axis
        applied = decoded["/hil/applied_wrench"]
        assert same([getattr(d.wrench.force, axis) for d in applied], series[f"applied_force_{axis}"])
        assert same([getattr(d.vector, axis) for d in decoded["/hil/contact_force"]], series[f"contact_force_{axis}"])
        assert same([getattr(d.pose.position, axis) for d in decoded["/hil/tip/commanded"]], series[f"tip_position_{axis}"])
        assert same([getattr(d.pose.position, axis) for d in decoded["/hil/tip/actual"]],
                    series[f"actual_tip_position_{axis}"])
        assert same([getattr(d.twist.linear, axis) for d in decoded["/hil/tip/commanded_velocity"]],
                    series[f"tip_velocity_{axis}"])
        assert same([getattr(d.twist.angular, axis) for d in decoded["/hil/tip/commanded_velocity"]],
                    series[f"angular_velocity_{axis}"])
        assert same([getattr(d.twist.linear, axis) for d in decoded["/hil/tip/actual_velocity"]],
                    series[f"actual_tip_velocity_{axis}"])
    assert {d.header.frame_id for d in wrench} == {"sensor"}
    assert {d.header.frame_id for d in decoded["/hil/tip/commanded"]} == {"t"}
    q = decoded["/hil/tip/commanded"][0].pose.orientation
    assert math.isclose(q.x**2 + q.y**2 + q.z**2 + q.w**2, 1.0, rel_tol=1e-12)
    assert same([d.energy for d in decoded["/hil/energy"]], series["energy"])
    if compensator == "pida":
        assert same([d.stiffness for d in decoded["/hil/estimates"]], series["stiffness_estimate"])
        assert same([d.damping for d in decoded["/hil/estimates"]], series["damping_estimate"])
        assert same([d.observed_energy for d in decoded["/hil/energy"]], series["observed_energy"])
    else:
        assert all(math.isnan(d.observed_energy) for d in decoded["/hil/energy"])

    # the sensor frame in t, the events, the metadata
    (tf,) = decoded["/tf_static"]
    (transform,) = tf.transforms
    assert (transform.header.frame_id, transform.child_frame_id) == ("t", "sensor")
    metrics = json.loads((out / "metrics.json").read_text())
    events = [d for d in decoded["/hil/events"]]
    assert events[0].msg.startswith("simulation run of paper-table1 started: compensator " + compensator)
    assert events[0].level == 20 and events[0].name == "hilcontact"
    assert f"status {metrics['status']}" in events[-1].msg
    if metrics["status"] == "diverged":
        assert events[-1].level == 40 and metrics["reason"] in events[-1].msg
    meta = metadata["hilcontact"]
    assert (meta["kind"], meta["scenario"], meta["compensator"]) == ("simulation", "paper-table1", compensator)
    assert json.loads(meta["scenario_json"])["name"] == "paper-table1"

    # an independent decoder of the same bytes: rosbags' CDR deserializer
    store = rosbags_store(summary)
    scene_store = own_definitions_store(summary, SCHEMAS["/hil/scene"])
    for topic, items in messages.items():
        for message, decoded_message in (items[0], items[-1]):
            msg = (scene_store if topic == "/hil/scene" else store).deserialize_cdr(message.data, SCHEMAS[topic])
            if topic == "/hil/measured_wrench":
                assert (msg.wrench.force.x, msg.wrench.torque.z) == (
                    decoded_message.wrench.force.x, decoded_message.wrench.torque.z)
            if topic == "/hil/events":
                assert msg.msg == decoded_message.msg
            if hasattr(msg, "header"):
                assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == (
                    decoded_message.header.stamp.sec, decoded_message.header.stamp.nanosec,
                    decoded_message.header.frame_id)
    energy = store.deserialize_cdr(messages["/hil/energy"][-1][0].data, "hilcontact_msgs/msg/Energy")
    assert energy.energy == series["energy"].iloc[-1]

    # the facility in 3-D, as the live view draws it: every 33rd tick, the rods from the time
    # series, the servicer frames in t
    scene_ticks = list(range(0, n, SCENE_EVERY))
    assert [m.log_time for m, _ in messages["/hil/scene"]] == [t[k] for k in scene_ticks]
    for (_, markers), k in zip(messages["/hil/scene"], scene_ticks):
        by_id = {m.id: m for m in markers.markers}
        assert {0, 1, 2, 3} <= set(by_id) and all(m.header.frame_id == "t" for m in markers.markers)
        tip, actual = by_id[0].points[1], by_id[1].points[1]
        assert (tip.x, tip.y, tip.z) == tuple(series[f"tip_position_{a}"].iloc[k] for a in "xyz")
        assert (actual.x, actual.y, actual.z) == tuple(series[f"actual_tip_position_{a}"].iloc[k] for a in "xyz")
        assert len(markers.markers) == 4 + 2  # the rods, contact, force arrow, paper-table1's two walls
    for _, frames in messages["/tf"]:
        assert sorted(f.child_frame_id for f in frames.transforms) == ["servicer", "servicer_actual"]


def test_an_existing_mcap_file_is_refused_unless_forced(core, tmp_path):
    path = tmp_path / "mine.mcap"
    path.write_text("my own file")
    result = invoke("run", "paper-table1", "--out", str(tmp_path / "r"), "--no-plots", "--mcap", str(path))
    assert_one_error_line(result, f"--mcap {path}", "exists", "--force")
    assert path.read_text() == "my own file" and not (tmp_path / "r").exists()
    # a folder, or a file inside --out (replaced as a whole): refused too, before anything runs
    result = invoke("run", "paper-table1", "--out", str(tmp_path / "r"), "--no-plots", "--mcap", str(tmp_path))
    assert_one_error_line(result, "is a directory")
    result = invoke("run", "paper-table1", "--out", str(tmp_path / "r"), "--no-plots",
                    "--mcap", str(tmp_path / "r" / "run.mcap"))
    assert_one_error_line(result, "inside --out")
    assert not (tmp_path / "r").exists()
    # hil and demo-rt refuse it too, before anything is opened or started
    for command in (["demo-rt"], ["hil", "paper-table1", "--sensor", "127.0.0.1"]):
        result = invoke(*command, "--out", str(tmp_path / "rt"), "--mcap", str(path))
        assert_one_error_line(result, f"--mcap {path}", "exists", "--force")
    assert path.read_text() == "my own file" and not (tmp_path / "rt").exists()
    # --force replaces it
    result = invoke("run", "paper-table1", "--out", str(tmp_path / "r"), "--no-plots", "--mcap", str(path), "--force")
    assert result.exit_code == 0, result.output
    messages, _, _ = read_decoded(path)
    assert len(messages["/hil/measured_wrench"]) == len(pd.read_parquet(tmp_path / "r" / "timeseries.parquet"))


def test_simulate_from_python_records_and_refuses_to_overwrite(core, tmp_path):
    import hilcontact as hc
    from hilcontact.errors import RealtimeError, RealtimeOptionError

    path = tmp_path / "sub" / "api.mcap"
    run = hc.simulate("paper-table1", mcap=path)
    assert run.mcap is not None and run.mcap["complete"] and run.mcap["write_errors"] == 0
    assert run.mcap["path"] == str(path) and run.mcap["bytes"] == path.stat().st_size
    n = len(run.timeseries)
    assert run.mcap["messages"] == len(PER_TICK) * n + 2 + 1 + len(SCENE) * scene_messages(n)
    with pytest.raises(RealtimeOptionError, match="exists"):
        hc.simulate("paper-table1", mcap=path)
    again = hc.simulate("paper-table1", mcap=path, overwrite=True)
    assert again.mcap["messages"] == run.mcap["messages"]
    assert hc.simulate("paper-table1").mcap is None
    blocked = tmp_path / "file"
    blocked.write_text("x")
    with pytest.raises(RealtimeError, match=str(blocked / "x.mcap")):
        hc.simulate("paper-table1", mcap=blocked / "x.mcap")


def test_a_real_time_run_across_processes_records_every_channel(core, tmp_path):
    out, path = tmp_path / "rt", tmp_path / "rt.mcap"
    with facility_process(tmp_path) as ports:
        result = run_hil(ports, out, ROBOT_DELAY, "compensator.kind=pida", "simulation.duration=2.0",
                         extra=("--mcap", str(path)))
    assert result.returncode == 0, result.stderr + result.stdout
    assert f"mcap: {path}" in result.stdout.replace("\n", "")
    metrics = json.loads((out / "metrics.json").read_text())
    rt = metrics["realtime"]
    series = pd.read_parquet(out / "timeseries.parquet")
    n = rt["samples"]
    assert n == len(series) == 2001
    recorded = rt["mcap"]
    assert recorded["complete"] and recorded["write_errors"] == 0 and recorded["error"] is None
    assert recorded["path"] == str(path) and recorded["bytes"] == path.stat().st_size
    messages, summary, metadata = read_decoded(path)
    for topic in [*PER_TICK, "/hil/estimates", "/hil/loop_timing"]:
        assert len(messages[topic]) == n, topic
    for topic in SCENE:
        assert len(messages[topic]) == scene_messages(n), topic
    assert recorded["messages"] == sum(len(m) for m in messages.values()) == summary.statistics.message_count
    decoded = {topic: [d for _, d in m] for topic, m in messages.items()}
    assert [stamp(d) for d in decoded["/hil/measured_wrench"]] == ns(series["time"])
    assert same([d.wrench.force.x for d in decoded["/hil/measured_wrench"]], series["measured_force_x"])
    assert same([d.pose.position.x for d in decoded["/hil/tip/actual"]], series["actual_tip_position_x"])
    assert same([d.wake_latency for d in decoded["/hil/loop_timing"]], series["wake_latency"])
    assert same([d.sensor_age for d in decoded["/hil/loop_timing"]], series["sensor_age"])
    assert same([d.stiffness for d in decoded["/hil/estimates"]], series["stiffness_estimate"])
    events = [d.msg for d in decoded["/hil/events"]]
    assert events[0].startswith("realtime run of paper-table1 started: compensator pida")
    assert any(e.startswith("stop: completed at 2.000 s") for e in events), events
    assert any(e.startswith("run ended at 2.000 s: status ") and "exit code 0" in e for e in events), events
    assert any(e.startswith("loop: 2001 ticks") for e in events), events
    assert metadata["hilcontact"]["kind"] == "realtime"


def test_a_run_killed_with_sigkill_reads_up_to_its_last_complete_chunk(core, tmp_path):
    path = tmp_path / "killed.mcap"
    with facility_process(tmp_path) as ports:
        cmd = hil_command(ports, tmp_path / "never", ROBOT_DELAY, "compensator.kind=pida", "simulation.duration=60",
                          watchdog_ms=2000, extra=("--mcap", str(path)))
        process = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            # about 0.55 MB per 0.5 s chunk at 1 kHz: wait for a few chunks, then kill
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and process.poll() is None:
                if path.exists() and path.stat().st_size > 2_000_000:
                    break
                time.sleep(0.05)
            assert process.poll() is None, process.stderr.read() if process.stderr else ""
            assert path.stat().st_size > 2_000_000, "the file did not grow"
            process.send_signal(signal.SIGKILL)
            process.wait(timeout=30)
        finally:
            if process.poll() is None:
                process.kill()
    assert process.returncode == -signal.SIGKILL
    data = path.read_bytes()
    assert not data.endswith(b"\x89MCAP0\r\n"), "no footer: the run was killed"
    assert not (tmp_path / "never").exists()
    # a streaming reader (no summary or footer needed) reads up to the last complete chunk
    times: dict[str, list[int]] = defaultdict(list)
    order, ended_by = [], None
    with open(path, "rb") as f:
        reader = mcap_reader.NonSeekingReader(f, decoder_factories=[mcap_ros2_decoder.DecoderFactory()])
        try:
            # in file order: sorting by log time would read the whole file before yielding
            for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
                times[channel.topic].append(message.log_time)
                order.append(message.log_time)
                if channel.topic == "/hil/measured_wrench":
                    assert decoded.header.frame_id == "sensor"
        except McapError as exc:  # the cut: a chunk not (completely) written
            ended_by = exc
    counts = Counter({topic: len(t) for topic, t in times.items()})
    ticks = counts["/hil/measured_wrench"]
    assert ticks >= 1500, counts  # at least three 0.5 s chunks of 1 ms ticks
    assert ticks % 500 == 0, (ticks, ended_by)  # whole chunks only: each holds 0.5 s of run time
    for topic in [*PER_TICK, "/hil/estimates", "/hil/loop_timing"]:
        assert counts[topic] == ticks, (topic, counts)
        assert times[topic] == [k * 1_000_000 for k in range(ticks)], topic
    assert order == sorted(order)
    assert counts["/tf_static"] == 1 and counts["/hil/events"] >= 1
