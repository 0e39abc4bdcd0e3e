"""The facility's dissipation (`[facility] dissipation`) and the paper-experiment presets that
assume it (docs/model.md, "The paper's experiments: assumptions")."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hilcontact as hc

ROOT = Path(__file__).resolve().parents[1]
QUIET = {"facility.robot_delay": 0.0, "facility.sensor_delay": 0.0, "facility.sensor_noise": 0.0,
         "facility.torque_noise": 0.0}


def rebounds(run: hc.Run, key: str = "collisions") -> np.ndarray:
    return np.array([c["rebound_speed"] for c in run.metrics[key] if c.get("rebound_speed") is not None])


@pytest.mark.parametrize("dissipation", [100.0, 300.0, 700.0])
def test_dissipation_acts_as_added_contact_damping_without_delay(core, dissipation):
    """At no delay the loop's contact is the facility's: a linear contact with c + d. Its
    rebounds match the ideal reference of a contact with that damping (within 0.5 %)."""
    lossy = hc.simulate(hc.load_scenario("paper-exp-2.64hz", {**QUIET, "facility.dissipation": dissipation}))
    damped = hc.simulate(hc.load_scenario("paper-exp-2.64hz", {**QUIET, "contact.damping": 130.0 + dissipation}))
    hil, reference = rebounds(lossy), rebounds(damped, "reference_collisions")
    n = min(len(hil), len(reference))
    assert n >= 3
    np.testing.assert_allclose(hil[:n], reference[:n], rtol=5e-3)
    # and the ideal reference of the lossy run does not have it: it keeps c = 130 N s/m
    np.testing.assert_allclose(rebounds(lossy, "reference_collisions")[:n],
                               rebounds(hc.simulate(hc.load_scenario("paper-exp-2.64hz", QUIET)), "reference_collisions")[:n])
    assert (hil[:n] < rebounds(lossy, "reference_collisions")[:n]).all()


def test_zero_dissipation_is_todays_facility(core):
    base = hc.simulate(hc.load_scenario("paper-exp-2.64hz", {"compensator.kind": "pida"}))
    zero = hc.simulate(hc.load_scenario("paper-exp-2.64hz", {"compensator.kind": "pida", "facility.dissipation": 0.0}))
    assert base.metrics["collisions"] == zero.metrics["collisions"]
    assert base.timeseries.equals(zero.timeseries)


def test_dissipation_is_range_checked():
    with pytest.raises(hc.ScenarioError, match="facility.dissipation"):
        hc.load_scenario("paper-table1", {"facility.dissipation": -1.0})


@pytest.mark.parametrize("hz", ["1.93hz", "2.64hz"])
def test_facility_presets_are_the_experiments_plus_the_assumed_losses(hz):
    plain = hc.load_scenario(f"paper-exp-{hz}").to_dict()
    lossy = hc.load_scenario(f"paper-exp-{hz}-facility").to_dict()
    assert lossy["facility"].pop("dissipation") == 500.0 and plain["facility"].pop("dissipation") == 0.0
    for key in ("name", "description"):
        plain.pop(key), lossy.pop(key)
    assert lossy == plain
    shipped = ROOT / "python" / "hilcontact" / "scenarios" / f"paper-exp-{hz}-facility.toml"
    assert shipped.read_text(encoding="utf-8") == (ROOT / "scenarios" / shipped.name).read_text(encoding="utf-8")


def test_facility_presets_decay_like_figs_14_15(core):
    """Qualitatively as the paper's Figs. 14-15: no compensation diverges; PIDA's rebound
    falls to about half the initial 20 mm/s after four collisions at 2.64 Hz, and less far
    at 1.93 Hz (the rebounds converge faster at the higher contact frequency)."""
    fourth = {}
    for hz in ("1.93hz", "2.64hz"):
        preset = f"paper-exp-{hz}-facility"
        assert hc.simulate(hc.load_scenario(preset, {"compensator.kind": "none"})).status == "diverged"
        pida = rebounds(hc.simulate(hc.load_scenario(preset, {"compensator.kind": "pida"})))
        assert len(pida) >= 4 and np.all(np.diff(pida) < 0)  # decaying at every collision
        fourth[hz] = pida[3] / 0.02
    assert 0.4 <= fourth["2.64hz"] <= 0.6
    assert fourth["1.93hz"] > fourth["2.64hz"]
