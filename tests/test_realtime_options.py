"""Real-time options grouped per device link, and the flat keys of earlier versions."""

from __future__ import annotations

import json

import pytest

from hilcontact.errors import RealtimeOptionError

core = pytest.importorskip("hilcontact._core")

from hilcontact.realtime import ANY_KIND, LEGACY_KEYS, _options, realtime_defaults  # noqa: E402


def test_defaults_are_grouped_with_kinds_and_list_the_protocols():
    d = realtime_defaults()
    assert d["runtime"]["sensor"] == {
        "kind": "rdt", "host": "127.0.0.1", "port": 49152, "http_port": 80,
        "counts_per_force": None, "counts_per_torque": None, "local_port": 0, "bias": False,
    }
    assert d["runtime"]["robot"]["kind"] == "egm" and d["runtime"]["robot"]["port"] == 6510
    assert d["protocols"] == {"sensor": ["rdt", "sri"], "robot": ["egm", "rsi"]}


def test_flat_legacy_keys_move_into_their_link():
    flat = {"sensor_port": 5000, "http_port": 8080, "egm_port": 6600, "egm_bind_host": "127.0.0.1",
            "counts_per_force": 1e6, "counts_per_torque": 1e6, "connect_timeout": 0.3, "robot_host": None}
    assert json.loads(_options(flat, "runtime")) == {
        "sensor": {"kind": "rdt", "port": 5000, "http_port": 8080, "counts_per_force": 1e6, "counts_per_torque": 1e6},
        "robot": {"kind": "egm", "port": 6600, "bind_host": "127.0.0.1"},
        "connect_timeout": 0.3,
    }
    # every legacy key names a key of its link's defaults
    d = realtime_defaults()["runtime"]
    for link, kind, key in LEGACY_KEYS["runtime"].values():
        assert kind in (d[link]["kind"], ANY_KIND) and key in d[link]


def test_grouped_and_flat_keys_merge_and_kinds_are_checked():
    merged = json.loads(_options({"robot": {"kind": "egm", "port": 7000}, "egm_bind_host": "127.0.0.1"}, "runtime"))
    assert merged["robot"] == {"kind": "egm", "port": 7000, "bind_host": "127.0.0.1"}
    assert json.loads(_options({"sensor": {"port": 1}}, "runtime"))["sensor"] == {"kind": "rdt", "port": 1}
    with pytest.raises(RealtimeOptionError, match="egm_port.*robot kind 'egm', not 'rsi'"):
        _options({"robot": {"kind": "rsi"}, "egm_port": 1}, "runtime")
    with pytest.raises(RealtimeOptionError, match="unknown runtime option 'egm_prot'"):
        _options({"egm_prot": 1}, "runtime")


def test_the_rust_side_rejects_unknown_kinds_and_foreign_keys(tmp_path):
    from hilcontact.realtime import run_hil

    for bad in ({"robot": {"kind": "fri"}}, {"sensor": {"kind": "rdt", "offset_mm": [0, 0, 0]}}):
        with pytest.raises(RealtimeOptionError):
            run_hil("paper-table1", bad)


def test_scheduling_defaults_and_the_cli_flags():
    assert realtime_defaults()["runtime"]["scheduling"] == {"priority": 80, "lock_memory": True, "cpu": None}
    from hilcontact.cli.realtime_commands import _scheduling_options

    assert _scheduling_options(None, False, None) is None  # the Rust defaults
    assert _scheduling_options(0, True, 1) == {"priority": 0, "lock_memory": False, "cpu": 1}
    assert json.loads(_options({"scheduling": _scheduling_options(50, False, None)}, "runtime")) == {
        "scheduling": {"priority": 50}
    }


@pytest.mark.parametrize(("scheduling", "fragment"), [
    ({"priority": 100}, "scheduling.priority"),
    ({"cpu": 9999}, "scheduling.cpu: CPU 9999 does not exist"),
    ({"policy": "fifo"}, "policy"),
])
def test_bad_scheduling_options_are_refused_before_connecting(scheduling, fragment):
    from hilcontact.realtime import run_hil

    with pytest.raises(RealtimeOptionError, match=fragment):
        run_hil("paper-table1", {"scheduling": scheduling, "connect_timeout": 0.2})


def test_the_report_line_says_what_was_granted_and_what_was_refused():
    from hilcontact.cli.reports import _scheduling_line

    granted = {"policy": "fifo", "priority": 80, "fifo_granted": True, "memory_locked": True, "cpu": None,
               "pinned": False, "refused": []}
    assert _scheduling_line(granted) == "scheduling: SCHED_FIFO 80 granted, memory locked, not pinned"
    refused = {"policy": "other", "priority": 0, "fifo_granted": False, "memory_locked": False, "cpu": 1,
               "pinned": True, "refused": ["SCHED_FIFO priority 80: EPERM (Operation not permitted): needs CAP_SYS_NICE"]}
    assert _scheduling_line(refused) == (
        "scheduling: normal priority, memory not locked, pinned to CPU 1 "
        "(refused: SCHED_FIFO priority 80: EPERM (Operation not permitted): needs CAP_SYS_NICE)"
    )


def test_sensor_host_and_port_go_to_any_sensor_kind():
    """`hil --sensor-protocol sri --sensor HOST --sensor-port P`: the flat host and port are the
    SRI box's; an RDT-only key with kind sri is refused."""
    grouped = json.loads(_options({"sensor": {"kind": "sri"}, "sensor_host": "192.168.0.108", "sensor_port": 4008}, "runtime"))
    assert grouped["sensor"] == {"kind": "sri", "host": "192.168.0.108", "port": 4008}
    assert "sri" in realtime_defaults()["protocols"]["sensor"]
    with pytest.raises(RealtimeOptionError, match="http_port.*sensor kind 'rdt', not 'sri'"):
        _options({"sensor": {"kind": "sri"}, "http_port": 80}, "runtime")


def test_robot_host_goes_to_any_robot_kind():
    """`hil --robot-protocol rsi --robot HOST`: the robot's host is the KUKA controller's."""
    grouped = json.loads(_options({"robot": {"kind": "rsi"}, "robot_host": "10.0.0.2"}, "runtime"))
    assert grouped["robot"] == {"kind": "rsi", "robot_host": "10.0.0.2"}
    grouped = json.loads(_options({"robot_host": "10.0.0.3"}, "runtime"))
    assert grouped["robot"] == {"kind": "egm", "robot_host": "10.0.0.3"}
