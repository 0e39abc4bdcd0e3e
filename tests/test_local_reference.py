"""The local (restarted) reference of each collision (docs/model.md "Metrics"): its errors in
the metrics dict, the summary's worst from judge_from on and the collision table, never the
verdict."""

from __future__ import annotations

import math

import pytest

import hilcontact as hc

LOCAL = ["local_start", "local_velocity_error", "local_cof", "local_tangential_impulse_error",
         "local_normal_impulse_error"]


@pytest.fixture(scope="module")
def geometry_80ms(core) -> hc.Run:
    """rod-in-frame, model-mediated at 80 ms with the shapes' geometry known (law unknown)."""
    return hc.simulate(hc.load_scenario("rod-in-frame", {
        "compensator.kind": "model-mediated", "compensator.prior_shapes": "geometry",
        "facility.robot_delay": 0.08, "facility.sensor_delay": 0.005, "facility.sensor_noise": 0.2,
        "metrics.local_references": True,
    }))


def test_each_later_contact_is_faithful_to_its_local_reference(geometry_80ms):
    run = geometry_80ms
    table = run.collision_table()
    for key in LOCAL:
        assert key in table.columns
    later = table.loc[2:]
    assert len(later) >= 2
    assert (later["local_velocity_error"] <= 0.03).all(), later["local_velocity_error"]
    assert ((later["local_cof"] - 1.0).abs() <= 0.005).all(), later["local_cof"]
    # the global metrics stay the verdict: collision 3 is far off the global reference
    assert table.loc[3, "velocity_error"] > 0.5
    assert run.status == "unfaithful"
    # the restart lies before the collision, by at least the loop's lag
    assert (table["local_start"] <= table["start"] - 0.08).all()


def test_the_summary_holds_the_worst_from_judge_from_on(core):
    over = {"compensator.kind": "model-mediated", "compensator.prior_shapes": "geometry",
            "facility.robot_delay": 0.08, "facility.sensor_delay": 0.005, "facility.sensor_noise": 0.2,
            "metrics.local_references": True}
    every = hc.simulate(hc.load_scenario("rod-in-frame", over)).metrics
    later = hc.simulate(hc.load_scenario("rod-in-frame", {**over, "metrics.judge_from": 2})).metrics
    first = every["collisions"][0]["local_velocity_error"]
    rest = [c["local_velocity_error"] for c in later["collisions"][1:] if c["local_velocity_error"] is not None]
    assert every["summary"]["worst_local_velocity_error"] == pytest.approx(max([first, *rest]))
    assert later["summary"]["worst_local_velocity_error"] == pytest.approx(max(rest))
    assert later["summary"]["worst_local_velocity_error"] < 0.03 < first
    # judge_from changes no global number
    assert every["summary"]["worst_velocity_error"] == later["summary"]["worst_velocity_error"]


def test_a_diverged_run_has_no_local_errors(core):
    m = hc.simulate(hc.load_scenario("paper-table1", {"metrics.local_references": True})).metrics
    assert m["status"] == "diverged"
    assert all(c[key] is None for c in m["collisions"] for key in LOCAL)
    worst = m["summary"]["worst_local_velocity_error"]
    assert worst is None or math.isnan(worst)  # NaN, written as null in JSON


def test_the_local_references_are_asked_for(core):
    over = {"compensator.kind": "pida", "facility.robot_delay": 0.02}
    off = hc.simulate(hc.load_scenario("paper-table1", over)).metrics
    on = hc.simulate(hc.load_scenario("paper-table1", {**over, "metrics.local_references": True})).metrics
    assert all(c["local_velocity_error"] is None for c in off["collisions"])
    assert all(c["local_velocity_error"] is not None for c in on["collisions"])
    assert off["summary"]["worst_velocity_error"] == on["summary"]["worst_velocity_error"]
