"""Independent open-source clients against the emulated facility: the ``NetFT`` package as the
F/T sensor's client (RDT, fixed port 49152), ``abb-robot-client`` as the PC side of EGM; plus
the RDT sequence numbers and ``/netftapi2.xml`` as a real Net F/T keeps and serves them."""

from __future__ import annotations

import socket
import struct
import time
import urllib.request

import numpy as np
import pytest

import hilcontact as hc
from hilcontact.realtime import start_facility

# The rod tip starts 5 mm inside the front wall (x = 10 mm) and the robot holds it there: the
# sensor reads the spring force k·d = 176275 N/m · 5 mm = 881.375 N on the frame (+x) and its
# moment about the sensor origin (0, 0, -0.15) m: r × F = (0.015, 0, 0.15) × (881.375, 0, 0).
PRESSED = {"servicer.position": [-0.985, 0.0, 0.0], "servicer.velocity": [0.0, 0.0, 0.0]}
PRESSED_COUNTS = [881_375_000, 0, 0, 0, 132_206_250, 0]  # at 1e6 counts per N and per N m


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def udp_port_is_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


@pytest.fixture
def pressed_facility(core):
    """The emulated facility with the rod pressed into the wall, sensor on port 49152 (NetFT
    cannot use another one)."""
    if not udp_port_is_free(49152):
        pytest.skip("UDP port 49152 (fixed in the NetFT client) is in use")
    scenario = hc.load_scenario("paper-table1", PRESSED)
    options = {"sensor_port": 49152, "http_port": free_port(socket.SOCK_STREAM), "egm_port": free_port()}
    with start_facility(scenario, options) as facility:
        time.sleep(0.05)
        yield facility


def test_netft_client_reads_the_emulated_sensor(pressed_facility):
    from NetFT import Sensor

    sensor = Sensor("127.0.0.1")
    sensor.sock.settimeout(2.0)
    try:
        counts = sensor.getMeasurement()  # one record: command 0x0002 with sample count 1
        assert counts == pytest.approx(PRESSED_COUNTS, abs=2)
        # NetFT's software tare and the sensor's own bias command
        sensor.send(0x0042)
        time.sleep(0.02)
        assert sensor.getMeasurement() == pytest.approx([0] * 6, abs=2)
        sent_before = pressed_facility.status()["rdt_sent"]
        sensor.startStreaming(handler=True)
        time.sleep(0.3)
        sensor.stopStreaming()
        streamed = pressed_facility.status()["rdt_sent"] - sent_before
        # 1 kHz for 0.3 s plus the 0.1 s NetFT waits before it sends the stop
        assert 300 <= streamed <= 480, streamed
        time.sleep(0.05)
        after_stop = pressed_facility.status()["rdt_sent"]
        time.sleep(0.1)
        assert pressed_facility.status()["rdt_sent"] == after_stop  # stop (0x0000) stops
    finally:
        sensor.sock.close()


def test_netftapi2_xml_gives_the_counts(pressed_facility):
    url = f"http://{pressed_facility.addresses['http']}/netftapi2.xml"
    with urllib.request.urlopen(url, timeout=2) as response:
        text = response.read().decode()
    assert "<cfgcpf>1000000</cfgcpf>" in text and "<cfgcpt>1000000</cfgcpt>" in text
    assert "<comrdtrate>1000</comrdtrate>" in text and "<scfgfu>N</scfgfu>" in text


def test_rdt_sequences_sample_count_and_bad_requests(core):
    scenario = hc.load_scenario("paper-table1", PRESSED)
    port = free_port()
    with start_facility(scenario, {"sensor_port": port, "http_port": 0, "egm_port": free_port()}) as facility:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.settimeout(1.0)
            s.sendto(b"\x12\x34\x00", ("127.0.0.1", port))  # wrong size
            s.sendto(struct.pack("!HHI", 0x4321, 2, 5), ("127.0.0.1", port))  # wrong header
            s.sendto(struct.pack("!HHI", 0x1234, 0x0077, 5), ("127.0.0.1", port))  # unknown command
            s.sendto(struct.pack("!HHI", 0x1234, 2, 5), ("127.0.0.1", port))  # 5 records
            records = [struct.unpack("!IIIiiiiii", s.recv(100)) for _ in range(5)]
            s.settimeout(0.1)
            with pytest.raises(socket.timeout):
                s.recv(100)  # exactly sample_count records
            time.sleep(0.05)
            s.settimeout(1.0)
            s.sendto(struct.pack("!HHI", 0x1234, 2, 2), ("127.0.0.1", port))
            later = [struct.unpack("!IIIiiiiii", s.recv(100)) for _ in range(2)]
    rdt = [r[0] for r in records + later]
    ft = [r[1] for r in records + later]
    assert rdt == list(range(rdt[0], rdt[0] + 7))  # one per record sent
    assert all(b - a == 1 for a, b in zip(ft[:5], ft[1:5]))  # one per sample (1 kHz)
    assert ft[5] - ft[4] >= 50  # samples taken while not streaming still count
    assert all(r[2] == 0 for r in records)  # status healthy
    assert list(records[0][3:]) == pytest.approx(PRESSED_COUNTS, abs=2)
    assert facility.status()["rdt_bad_requests"] == 3


def test_abb_robot_client_drives_the_emulated_robot(core):
    from abb_robot_client.egm import EGM

    egm_port = free_port()
    client = EGM(port=egm_port)
    scenario = hc.load_scenario("paper-table1")  # robot delay 10 ms; rod tip 5 mm before the wall
    try:
        with start_facility(scenario, {"sensor_port": free_port(), "http_port": 0, "egm_port": egm_port}) as facility:
            ok, state = client.receive_from_robot(timeout=2.0)
            assert ok
            position, orientation = state.cartesian
            assert position == pytest.approx([-995.0, 0.0, 0.0], abs=1e-9)  # mm: the servicer in t
            assert orientation == pytest.approx([1.0, 0.0, 0.0, 0.0])
            assert state.motors_on and state.rapid_running
            assert state.cartesian_planned[0] == pytest.approx([-995.0, 0.0, 0.0], abs=1e-9)
            target = np.array([-995.0, 3.0, 0.0])  # 3 mm sideways: parallel to the walls
            first_sent = None
            moved_at = None
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                ok, state = client.receive_from_robot(timeout=0.1)
                if not ok:
                    continue
                if state.cartesian[0][1] > 1.5 and moved_at is None:
                    moved_at = time.monotonic()
                if moved_at is not None and time.monotonic() - moved_at > 0.1:
                    break
                assert client.send_to_robot_cart(target, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(6))
                first_sent = first_sent or time.monotonic()
            assert moved_at is not None, "the robot never followed the correction"
            assert state.cartesian[0] == pytest.approx(target, abs=1e-6)
            assert state.cartesian_planned[0] == pytest.approx(target, abs=1e-6)
            # the configured response lag (10 ms) is a floor; 4 ms feedback and scheduling add to it
            assert 0.009 <= moved_at - first_sent < 0.3
            status = facility.status()
            assert status["corrections"] > 10
            # the client's sequence numbers step by 2: gaps are accepted, nothing is dropped
            assert status["corrections_dropped"] == 0
            # feedback every 4 ms of the emulator's time
            assert abs(status["egm_sent"] - status["time"] * 250) <= 2, status
    finally:
        client.close()
