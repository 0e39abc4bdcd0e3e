"""The live view across processes on loopback: `hilcontact demo-rt --live` (and `run --live`)
served to a minimal Foxglove WebSocket client written here on the standard library (the
`foxglove.sdk.v1` subprotocol, the SDK's name of `foxglove.websocket.v1`): every force sample
at the loop's rate, the scene, the operator's stop (exit 3, stop `operator`) and its refusal
without --live-control; the address rule; the layout."""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from hilcontact.scenario import load_scenario
from test_cli import assert_one_error_line, invoke

SUBPROTOCOL = "foxglove.sdk.v1"


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Viewer:
    """A WebSocket client of the Foxglove protocol: handshake, frames (client frames masked),
    advertisements, subscriptions, service calls."""

    def __init__(self, port: int, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)
        self.sock.settimeout(30)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                           f"Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: {SUBPROTOCOL}\r\n\r\n").encode())
        self.buf = b""
        while b"\r\n\r\n" not in self.buf:
            self.buf += self.sock.recv(4096)
        head, self.buf = self.buf.split(b"\r\n\r\n", 1)
        assert head.startswith(b"HTTP/1.1 101"), head
        assert SUBPROTOCOL.encode() in head
        self.channels: dict[int, dict[str, Any]] = {}
        self.services: dict[str, int] = {}
        self.topics: dict[int, str] = {}
        while not self.channels or not self.services:
            kind, data = self.read()
            if kind == "text":
                m = json.loads(data)
                if m["op"] == "advertise":
                    self.channels.update({c["id"]: c for c in m["channels"]})
                elif m["op"] == "advertiseServices":
                    self.services.update({s["name"]: s["id"] for s in m["services"]})

    def _exact(self, n: int) -> bytes:
        while len(self.buf) < n:
            chunk = self.sock.recv(1 << 16)
            if not chunk:
                raise ConnectionError("closed")
            self.buf += chunk
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def read(self) -> tuple[str, bytes]:
        """One message: ("text" | "binary" | "close", payload) (fragments joined)."""
        payload, kind = b"", None
        while True:
            b0, b1 = self._exact(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._exact(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._exact(8))[0]
            data = self._exact(n)
            opcode = b0 & 0x0F
            if opcode == 8:
                return "close", data
            if opcode in (9, 10):  # ping, pong
                if opcode == 9:
                    self._send(10, data)
                continue
            kind = kind or {1: "text", 2: "binary"}.get(opcode, "binary")
            payload += data
            if b0 & 0x80:
                return kind, payload

    def _send(self, opcode: int, data: bytes) -> None:
        mask = os.urandom(4)
        n = len(data)
        head = bytes([0x80 | opcode])
        if n < 126:
            head += bytes([0x80 | n])
        elif n < 1 << 16:
            head += bytes([0x80 | 126]) + struct.pack(">H", n)
        else:
            head += bytes([0x80 | 127]) + struct.pack(">Q", n)
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def send_json(self, message: dict[str, Any]) -> None:
        self._send(1, json.dumps(message).encode())

    def subscribe_all(self) -> None:
        subs = [{"id": i, "channelId": cid} for i, cid in enumerate(self.channels)]
        self.topics = {i: self.channels[cid]["topic"] for i, cid in enumerate(self.channels)}
        self.send_json({"op": "subscribe", "subscriptions": subs})

    def call(self, service: str, call_id: int, payload: bytes = b"{}") -> None:
        self._send(2, struct.pack("<BIII", 2, self.services[service], call_id, 4) + b"json" + payload)

    def read_all(self, stop_at: float | None = None) -> dict[str, Any]:
        """Everything until the server closes: per topic the log times (ns); the first scene
        message; responses and failures of calls. Calls the stop once the force channel passes
        ``stop_at`` s."""
        seen: dict[str, Any] = {"times": {}, "scene": None, "responses": [], "failures": [], "events": []}
        stopped = False
        while True:
            try:
                kind, data = self.read()
            except (ConnectionError, OSError):
                break
            if kind == "close":
                break
            if kind == "binary" and data[0] == 1:
                sub, t = struct.unpack_from("<IQ", data, 1)
                topic = self.topics[sub]
                seen["times"].setdefault(topic, []).append(t)
                if topic == "/hil/scene" and seen["scene"] is None:
                    seen["scene"] = data[13:]
                if topic == "/hil/events":
                    seen["events"].append(data[13:])
                if stop_at is not None and not stopped and topic == "/hil/measured_wrench" and t >= stop_at * 1e9:
                    stopped = True
                    self.call("/hilcontact/stop", 7)
            elif kind == "binary" and data[0] == 3:
                seen["responses"].append(struct.unpack_from("<II", data, 1))
            elif kind == "text":
                m = json.loads(data)
                if m.get("op") == "serviceCallFailure":
                    seen["failures"].append(m)
        return seen


def demo_rt(tmp_path: Path, port: int, *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "hilcontact", "demo-rt", "--out", str(tmp_path / "run"), "--no-plots",
         "--live", str(port), "--live-wait", "60", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_a_viewer_gets_every_force_sample_the_scene_and_stops_the_run(tmp_path: Path) -> None:
    port = free_tcp_port()
    process = demo_rt(tmp_path, port, "--live-control", "--compensator", "none", "--set", "simulation.duration=4")
    viewer = Viewer(port)
    viewer.subscribe_all()
    seen = viewer.read_all(stop_at=0.8)
    out, err = process.communicate(timeout=120)
    assert process.returncode == 3, err
    assert f"live view: ws://127.0.0.1:{port}" in err
    assert "operator stop from client" in err
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    stop = metrics["realtime"]["stop"]
    assert stop["kind"] == "operator" and stop["exit_code"] == 3 and 0.8 <= stop["time"] < 3.0, stop
    assert metrics["status"] == "stopped"
    # every tick of the force channel, in order, at the loop's period: the run's own samples
    series = pd.read_parquet(tmp_path / "run" / "timeseries.parquet")
    expected = [round(t * 1e9) for t in series["time"]]
    assert metrics["realtime"]["samples_dropped"] == 0
    assert seen["times"]["/hil/measured_wrench"] == expected
    assert len(seen["times"]["/hil/contact_force"]) == len(expected)
    # the scene: 30 Hz of run time, decodable with its advertised schema
    scene_times = seen["times"]["/hil/scene"]
    assert len(scene_times) == -(-len(expected) // 33)
    assert len(seen["times"]["/tf"]) == len(scene_times)
    assert seen["responses"] == [(next(iter([viewer.services["/hilcontact/stop"]])), 7)]
    decoder = pytest.importorskip("mcap_ros2._dynamic")
    schema = next(c for c in viewer.channels.values() if c["topic"] == "/hil/scene")
    decode = decoder.generate_dynamic(schema["schemaName"], schema["schema"])[schema["schemaName"]]
    markers = decode(seen["scene"]).markers
    assert [m.type for m in markers[:4]] == [4, 4, 2, 0]  # virtual rod, actual rod, contact, force
    walls = load_scenario("paper-table1").walls
    assert len(markers) == 4 + len(walls) and all(m.type == 1 for m in markers[4:])  # a plate per wall
    assert all(m.header.frame_id == "t" for m in markers)


def test_without_live_control_the_stop_is_refused_and_logged(tmp_path: Path) -> None:
    port = free_tcp_port()
    process = demo_rt(tmp_path, port, "--set", "simulation.duration=1")
    viewer = Viewer(port)
    viewer.subscribe_all()
    seen = viewer.read_all(stop_at=0.3)
    out, err = process.communicate(timeout=120)
    assert process.returncode == 0, err
    assert "refused from client" in err and "no --live-control" in err
    assert len(seen["failures"]) == 1 and "--live-control" in seen["failures"][0]["message"]
    assert any(b"refused from client" in e for e in seen["events"])
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["realtime"]["stop"]["kind"] == "completed"
    live = metrics["realtime"]["live"]
    assert live["refused_calls"] == 1 and live["stop_calls"] == 0 and live["control"] is False


@pytest.mark.parametrize(("args", "words"), [
    (["--live", "0.0.0.0:8765"], ["live.host", "--live-remote"]),
    (["--live", "localhost:99999"], ["--live", "PORT"]),
    (["--live-control"], ["--live-control", "needs --live"]),
])
def test_bad_live_options_are_one_line_errors_and_write_nothing(tmp_path: Path, args: list[str], words: list[str]) -> None:
    out = tmp_path / "run"
    result = invoke("hil", "paper-table1", "--sensor", "127.0.0.1", "--out", str(out), "--no-plots", *args)
    assert_one_error_line(result, *words)
    assert not out.exists()


def test_the_layout_names_channels_the_runs_have() -> None:
    result = invoke("layout")
    assert result.exit_code == 0, result.output
    layout = json.loads(result.stdout)
    topics = {"/hil/measured_wrench", "/hil/applied_wrench", "/hil/contact_force", "/hil/tip/commanded",
              "/hil/tip/actual", "/hil/tip/commanded_velocity", "/hil/tip/actual_velocity", "/hil/energy",
              "/hil/estimates", "/hil/loop_timing", "/hil/events", "/tf_static", "/hil/scene", "/tf"}
    panels = layout["configById"]
    paths = [p["value"] for c in panels.values() for p in c.get("paths", [])]
    assert paths and all(p.split(".")[0] in topics for p in paths), paths
    assert {c["serviceName"] for k, c in panels.items() if k.startswith("CallService")} == {
        "/hilcontact/stop", "/hilcontact/mark"}


def test_run_live_replays_a_simulation_to_a_viewer(tmp_path: Path) -> None:
    port = free_tcp_port()
    out = tmp_path / "run"
    process = subprocess.Popen(
        [sys.executable, "-m", "hilcontact", "run", "paper-table1", "--set", "simulation.duration=0.5",
         "--out", str(out), "--no-plots", "--live", str(port), "--speed", "5"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    viewer = Viewer(port)
    viewer.subscribe_all()
    begun = time.monotonic()
    seen = viewer.read_all()
    elapsed = time.monotonic() - begun
    _, err = process.communicate(timeout=120)
    assert process.returncode == 0, err
    series = pd.read_parquet(out / "timeseries.parquet")
    assert seen["times"]["/hil/measured_wrench"] == [round(t * 1e9) for t in series["time"]]
    # 0.5 s at 5x: at least 0.1 s of wall time (paced, not dumped)
    assert elapsed >= 0.09, elapsed
    assert "/hil/loop_timing" not in seen["times"]  # a simulation has no loop


def test_the_facility_serves_its_truth_and_the_scene_and_the_operator_stop_ends_it(tmp_path: Path) -> None:
    """`hilcontact facility --live --live-control` in its own process: a viewer gets every
    period of its channels (the facility's, not the virtual dynamics'), the scene, and its stop
    ends the facility with exit 3."""
    port = free_tcp_port()
    ports = [str(free_tcp_port()) for _ in range(3)]
    process = subprocess.Popen(
        [sys.executable, "-m", "hilcontact", "facility", "paper-table1", "--sensor-port", ports[0],
         "--http-port", ports[1], "--robot-port", ports[2], "--live", str(port), "--live-control",
         "--live-wait", "60", "--duration", "120"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        viewer = Viewer(port)
        topics = {c["topic"] for c in viewer.channels.values()}
        viewer.subscribe_all()
        seen = viewer.read_all(stop_at=0.5)
        out, err = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 3, err + out
    assert "stop: operator (live view)" in out, out
    assert "operator stop from client" in err
    assert f"live view 127.0.0.1:{port}: " in out and "stop calls 1" in out, out
    # the facility's truth: its own channels, none of the virtual dynamics'
    assert {"/hil/measured_wrench", "/hil/contact_force", "/hil/tip/commanded", "/hil/tip/actual",
            "/hil/loop_timing", "/facility/contact_moment", "/hil/scene", "/tf"} <= topics, topics
    assert not topics & {"/hil/applied_wrench", "/hil/energy", "/hil/estimates"}, topics
    # every period from the first, in order, at the facility's 1 ms period, none missing
    times = seen["times"]["/hil/measured_wrench"]
    assert len(times) >= 500 and times == [round(k * 1e-3 * 1e9) for k in range(len(times))]
    for topic in ("/hil/contact_force", "/hil/tip/actual", "/hil/loop_timing", "/facility/contact_moment"):
        assert seen["times"][topic] == times, topic
    assert len(seen["times"]["/hil/scene"]) == -(-len(times) // 33) and seen["scene"] is not None
    assert seen["responses"] == [(viewer.services["/hilcontact/stop"], 7)]
    events = b"".join(seen["events"])
    assert b"facility stopped by the operator" in events, events
