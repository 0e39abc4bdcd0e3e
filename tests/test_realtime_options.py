"""Real-time options grouped per device link, and the flat keys of earlier versions."""

from __future__ import annotations

import json

import pytest

from hilcontact.errors import RealtimeOptionError

core = pytest.importorskip("hilcontact._core")

from hilcontact.realtime import LEGACY_KEYS, _options, realtime_defaults  # noqa: E402


def test_defaults_are_grouped_with_kinds_and_list_the_protocols():
    d = realtime_defaults()
    assert d["runtime"]["sensor"] == {
        "kind": "rdt", "host": "127.0.0.1", "port": 49152, "http_port": 80,
        "counts_per_force": None, "counts_per_torque": None, "local_port": 0, "bias": False,
    }
    assert d["runtime"]["robot"]["kind"] == "egm" and d["runtime"]["robot"]["port"] == 6510
    assert d["protocols"] == {"sensor": ["rdt"], "robot": ["egm", "rsi"]}


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
        assert d[link]["kind"] == kind and key in d[link]


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
