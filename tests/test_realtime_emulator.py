"""The emulated facility's options grouped per device (and the flat keys of earlier versions),
unknown protocols rejected with the allowed ones, its socket errors counted, and
RealtimeError carrying the OS errno."""

from __future__ import annotations

import errno
import json
import socket
import time

import pytest

from hilcontact.errors import HilContactError, RealtimeError, RealtimeOptionError

core = pytest.importorskip("hilcontact._core")

from hilcontact.cli import cli  # noqa: E402
from hilcontact.scenario import load_scenario  # noqa: E402
from hilcontact.realtime import ANY_KIND, LEGACY_KEYS, _options, realtime_defaults, start_facility  # noqa: E402


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_facility_defaults_are_grouped_with_kinds():
    d = realtime_defaults()["facility"]
    assert d["sensor"] == {
        "kind": "rdt", "bind_host": "127.0.0.1", "port": 49152, "http_port": 80,
        "counts_per_force": 1e6, "counts_per_torque": 1e6, "force_unit": "N", "torque_unit": "N-m",
    }
    assert d["robot"] == {
        "kind": "egm", "host": "127.0.0.1", "port": 6510, "local_port": 0, "period": 0.004,
        "offset_mm": [0.0, 0.0, 0.0], "rotation": [1.0, 0.0, 0.0, 0.0], "robotware": 7,
    }
    assert d["silence_sensor_after"] is None and d["silence_robot_after"] is None
    assert d["sensor_offset"] == [0.0] * 6
    # every flat key of earlier versions names a key of its device's defaults
    for link, kind, key in LEGACY_KEYS["facility"].values():
        assert kind in (d[link]["kind"], ANY_KIND) and key in d[link], (link, key)


def test_flat_facility_keys_move_into_their_device_and_round_trip():
    flat = {"sensor_port": 5000, "http_port": 0, "egm_port": 6600, "egm_host": "127.0.0.1",
            "egm_period": 0.008, "egm_offset_mm": [1.0, 2.0, 3.0], "silence_robot_after": 2.0}
    grouped = {
        "sensor": {"kind": "rdt", "port": 5000, "http_port": 0},
        "robot": {"kind": "egm", "port": 6600, "host": "127.0.0.1", "period": 0.008, "offset_mm": [1.0, 2.0, 3.0]},
        "silence_robot_after": 2.0,
    }
    assert json.loads(_options(flat, "facility")) == grouped
    assert json.loads(_options(grouped, "facility")) == grouped  # grouped passes through
    with pytest.raises(RealtimeOptionError, match="unknown facility option 'egm_prot'"):
        _options({"egm_prot": 1}, "facility")


def test_the_emulator_runs_from_grouped_options(core):
    sensor_port, egm_port = free_port(), free_port()
    options = {"sensor": {"kind": "rdt", "port": sensor_port, "http_port": 0},
               "robot": {"kind": "egm", "port": egm_port}}
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as pc:
        pc.bind(("127.0.0.1", egm_port))
        pc.settimeout(5.0)
        with start_facility("paper-table1", options) as facility:
            assert facility.addresses["sensor"] == f"127.0.0.1:{sensor_port}"
            assert facility.addresses["robot_peer"] == facility.addresses["egm_peer"] == f"127.0.0.1:{egm_port}"
            assert pc.recv(2048)  # EGM feedback arrives where the robot group says
            status = facility.status()
    assert status["sensor_protocol"] == "RDT" and status["robot_protocol"] == "EGM"
    final = facility.stop()
    assert final["robot"]["sent"] >= 1
    assert final["io_errors"] == 0 and final["robot"]["send_errors"] == 0


@pytest.mark.parametrize("section", ["facility", "runtime"])
def test_an_unknown_protocol_is_rejected_listing_the_allowed_ones(section):
    with pytest.raises(RealtimeOptionError, match=r"robot.kind: unknown robot protocol 'fri'; allowed: egm, rsi"):
        _options({"robot": {"kind": "fri"}}, section)
    with pytest.raises(RealtimeOptionError, match=r"sensor.kind: unknown sensor protocol 'ftx'; allowed: rdt, sri"):
        _options({"sensor": {"kind": "ftx", "port": 1}}, section)


def test_the_rust_side_rejects_an_unknown_protocol_too(core):
    with pytest.raises(RealtimeOptionError, match=r"unknown variant `fri`, expected `egm` or `rsi`"):
        core.start_facility(load_scenario("paper-table1").to_json(), json.dumps({"robot": {"kind": "fri"}}))


def test_the_cli_offers_the_protocols_of_the_core():
    from click.testing import CliRunner

    runner = CliRunner()
    for command in ("facility", "demo-rt"):
        help_text = runner.invoke(cli, [command, "--help"], prog_name="hilcontact").output
        assert "--sensor-protocol [rdt|sri]" in help_text and "--robot-protocol [egm|rsi]" in help_text, help_text
    bad = runner.invoke(cli, ["facility", "paper-table1", "--robot-protocol", "fri"], prog_name="hilcontact")
    assert bad.exit_code == 2 and "--robot-protocol" in bad.output and "'fri'" in bad.output and "egm" in bad.output, bad.output
    bad = runner.invoke(cli, ["demo-rt", "--sensor-protocol", "ftx"], prog_name="hilcontact")
    assert bad.exit_code == 2 and "--sensor-protocol" in bad.output and "'ftx'" in bad.output and "rdt" in bad.output, bad.output


def test_the_emulators_send_errors_are_counted(core):
    # feedback to the broadcast address: the kernel refuses each send (no SO_BROADCAST)
    options = {"sensor_port": free_port(), "http_port": 0, "egm_host": "255.255.255.255", "egm_port": free_port()}
    with start_facility("paper-table1", options) as facility:
        deadline = time.monotonic() + 10.0  # generous: a busy machine
        while facility.status()["robot"]["send_errors"] < 5 and time.monotonic() < deadline:
            time.sleep(0.02)
    final = facility.stop()
    robot = final["robot"]
    assert robot["send_errors"] >= 5 and robot["sent"] == 0, final
    assert final["io_errors"] >= robot["send_errors"], final


def test_a_port_in_use_raises_realtime_error_with_errno(core):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        with pytest.raises(RealtimeError) as info:
            start_facility("paper-table1", {"sensor_port": port, "http_port": 0, "egm_port": free_port()})
    exc = info.value
    assert isinstance(exc, OSError) and isinstance(exc, HilContactError)
    assert not isinstance(exc, RealtimeOptionError)
    assert exc.errno == errno.EADDRINUSE
    assert exc.kind == "AddrInUse"
    assert f"cannot bind UDP 127.0.0.1:{port}" in exc.strerror and f"cannot bind UDP 127.0.0.1:{port}" in str(exc)


def test_errors_without_an_os_errno_have_none(core):
    # nothing listens: the runtime gives up connecting (not an OS error)
    options = {"sensor_port": free_port(), "counts_per_force": 1e6, "counts_per_torque": 1e6,
               "egm_port": free_port(), "egm_bind_host": "127.0.0.1", "connect_timeout": 0.2}
    from hilcontact.realtime import run_hil

    with pytest.raises(RealtimeError) as info:
        run_hil("paper-table1", options)
    assert info.value.errno is None and "no RDT record" in str(info.value)
