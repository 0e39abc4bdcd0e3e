"""`hilcontact check` against the emulated facility (in process, on loopback): a dry run with the
options of `hil` that reports both links and the verdict, and commands nothing."""

from __future__ import annotations

import json
import socket
from pathlib import Path
from typing import Any

from click.testing import CliRunner

import hilcontact as hc
from hilcontact.cli import cli
from hilcontact.realtime import check, start_facility


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def ports() -> dict[str, int]:
    return {"sensor": free_port(), "http": free_port(socket.SOCK_STREAM), "egm": free_port()}


def facility_options(p: dict[str, int], offset: list[float]) -> dict[str, Any]:
    return {
        "sensor": {"kind": "rdt", "port": p["sensor"], "http_port": p["http"]},
        "robot": {"kind": "egm", "port": p["egm"]},
        "sensor_offset": offset,
    }


def check_args(p: dict[str, int], *extra: str) -> list[str]:
    """`hilcontact check paper-table1` with the options `hil` would get (counts over HTTP)."""
    return [
        "check", "paper-table1", "--sensor", "127.0.0.1", "--sensor-port", str(p["sensor"]),
        "--http-port", str(p["http"]), "--egm-port", str(p["egm"]), "--egm-bind", "127.0.0.1", *extra,
    ]


def test_check_against_the_facility_would_start_and_commands_nothing(core, tmp_path: Path):
    p = ports()
    with start_facility("paper-table1", facility_options(p, [3.0, -2.0, 20.0, 0.0, 0.0, 0.0])) as facility:
        result = CliRunner().invoke(cli, check_args(p, "--out", str(tmp_path / "c")), prog_name="hilcontact")
        final = facility.stop()
    assert result.exit_code == 0, result.output
    out = " ".join(result.output.split())
    assert "verdict: a run would start" in out
    assert "offset F (3.0" in out and "|F| 20.3" in out, out
    assert "rod tip (5.0, 0.0, 0.0) mm, 0.0 mm from the scenario's start (5.0, 0.0, 0.0) mm (start_tolerance 5.0 mm)" in out, out
    assert "counts_per_force" in out
    assert final["corrections"] == 0 and final["robot"]["received"] == 0
    report = json.loads((tmp_path / "c" / "check.json").read_text())
    assert report["would_start"] is True and report["reasons"] == []
    assert abs(report["sensor"]["offset"][2] - 20.0) < 0.2
    assert report["robot"]["start_distance"] < 1e-3 and report["robot"]["stats"]["sent"] == 0


def test_check_with_an_80_n_offset_would_refuse(core):
    p = ports()
    with start_facility("paper-table1", facility_options(p, [0.0, 0.0, 80.0, 0.0, 0.0, 0.0])) as facility:
        result = CliRunner().invoke(cli, check_args(p, "--duration", "0.5"), prog_name="hilcontact")
        final = facility.stop()
    assert result.exit_code == 1, result.output
    out = " ".join(result.output.split())
    assert "verdict: a run would refuse:" in out
    assert "offset.max_force 50.0 N" in out, out
    assert final["corrections"] == 0


def test_a_scenario_that_starts_in_contact_would_refuse_to_measure_the_offset(core):
    p = ports()
    pressed = hc.load_scenario("paper-table1", {"servicer.position": [-0.985, 0.0, 0.0], "servicer.velocity": [0.0, 0.0, 0.0]})
    options = {
        "sensor": {"kind": "rdt", "host": "127.0.0.1", "port": p["sensor"], "http_port": p["http"]},
        "robot": {"kind": "egm", "port": p["egm"], "bind_host": "127.0.0.1"},
    }
    with start_facility(pressed, facility_options(p, [0.0] * 6)):
        report = check(pressed, options, duration=0.3)
    assert report["would_start"] is False
    assert len(report["reasons"]) == 1 and report["reasons"][0].startswith("offset.mode: the scenario starts in contact")
    assert report["sensor"]["offset_force"] > 800.0  # the rod is pressed into the wall
    # with the offset off, the same facility would start (on new ports: the first facility's
    # HTTP port may still be in TIME_WAIT)
    q = ports()
    options = {
        "sensor": {"kind": "rdt", "host": "127.0.0.1", "port": q["sensor"], "http_port": q["http"]},
        "robot": {"kind": "egm", "port": q["egm"], "bind_host": "127.0.0.1"},
    }
    with start_facility(pressed, facility_options(q, [0.0] * 6)):
        report = check(pressed, {**options, "offset": {"mode": "off"}}, duration=0.3)
    assert report["would_start"] is True, report["reasons"]
