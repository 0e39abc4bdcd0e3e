"""The facility's dissipation (`[facility] dissipation`), `pic`'s unclamped eq. (22)
(`[compensator] pull`) and the paper-experiment presets that assume them (docs/model.md, "The
paper's experiments: assumptions")."""

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


#: What `paper-exp-*-facility` adds to `paper-exp-*`: the assumptions its header states.
ASSUMED = {"facility.dissipation": 200.0, "facility.servo_frequency": 4.0, "facility.servo_damping": 0.7,
           "simulation.duration": 10.0, "compensator.kind": "pida", "compensator.pull": True}


@pytest.mark.parametrize("hz", ["1.93hz", "2.64hz"])
def test_facility_presets_are_the_experiments_plus_the_stated_assumptions(hz):
    plain = hc.load_scenario(f"paper-exp-{hz}", ASSUMED).to_dict()
    lossy = hc.load_scenario(f"paper-exp-{hz}-facility").to_dict()
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


def test_pic_decays_fastest_on_the_facility_presets_like_fig_14(core):
    """Qualitatively as the paper's Fig. 14: on each preset PIC's rebound falls below PIDA's and
    DAC's at every collision; at 2.64 Hz to about zero (below 15 % of the initial 20 mm/s)
    within four collisions, faster than at 1.93 Hz."""
    pic = {}
    for hz in ("1.93hz", "2.64hz"):
        preset = f"paper-exp-{hz}-facility"
        pic[hz] = rebounds(hc.simulate(hc.load_scenario(preset, {"compensator.kind": "pic"})))
        assert len(pic[hz]) >= 3 and np.all(np.diff(pic[hz]) < 0)
        for kind in ("pida", "dac"):
            other = rebounds(hc.simulate(hc.load_scenario(preset, {"compensator.kind": kind})))
            n = min(len(pic[hz]), len(other))
            assert n >= 3 and np.all(pic[hz][:n] < other[:n]), (hz, kind, pic[hz], other)
    assert pic["2.64hz"][min(3, len(pic["2.64hz"])) - 1] < 0.15 * 0.02
    assert np.all(pic["2.64hz"][:3] < pic["1.93hz"][:3])


def test_the_clamp_is_what_keeps_pic_from_decaying_on_the_facility_presets(core):
    """Assumption 3 is needed: with the no-pull clamp (the default) PIC's rebounds on the same
    facility grow instead (or the loop diverges)."""
    clamped = hc.simulate(hc.load_scenario("paper-exp-2.64hz-facility",
                                           {"compensator.kind": "pic", "compensator.pull": False}))
    speeds = rebounds(clamped)
    assert clamped.status == "diverged" or speeds[-1] > speeds[0]
    assert speeds[0] > 0.02


@pytest.mark.parametrize("pull", [False, True])
def test_pic_pulls_only_when_asked(core, pull):
    """`pull = false` (the default) never applies a force against the measured contact force;
    `pull = true` does, by up to about the spring force of the robot's lag, where the virtual
    rod tip has left the wall while the robot still presses."""
    r = hc.simulate(hc.load_scenario("paper-exp-2.64hz-facility", {"compensator.kind": "pic", "compensator.pull": pull}))
    ts = r.timeseries
    pressed = ts["measured_force_x"].abs() > 10.0
    along = (ts["applied_force_x"] * np.sign(ts["measured_force_x"]))[pressed]
    if pull:
        assert along.min() < -10.0
    else:
        assert along.min() >= -1e-9  # zero where clamped (up to rounding in the frames)


def test_pull_is_off_by_default_and_checked():
    assert hc.load_scenario("paper-exp-2.64hz", {"compensator.kind": "pic"}).compensator.pull is False
    with pytest.raises(hc.ScenarioError, match="compensator.pull"):
        hc.load_scenario("paper-exp-2.64hz", {"compensator.kind": "pic", "compensator.pull": 3})
