"""The Python schema and the Rust core share one set of compensator defaults."""

import json

import pytest

import hilcontact as hc

core = pytest.importorskip("hilcontact._core")


@pytest.mark.parametrize("kind", ["none", "pic", "dac", "pida", "tdpa-impedance", "tdpa-admittance"])
def test_python_defaults_are_the_core_defaults(kind):
    rust = {e["kind"]: e["defaults"] for e in json.loads(core.compensator_registry())}[kind]
    scenario = hc.load_scenario("paper-table1", {"compensator.kind": kind})
    python = json.loads(scenario.to_json())["compensator"]
    assert python == rust
