"""[contact.friction] from the Python side: the key, its ranges and messages, and the energy
friction dissipates in a run's reference and metrics."""

import subprocess
import sys

import pytest

import hilcontact as hc
from hilcontact.errors import ScenarioError


def test_a_frictional_run_books_friction_work_apart():
    run = hc.simulate(hc.load_scenario("oblique-6dof", overrides={"contact.friction.kinetic": 0.2,
                                                                  "facility.robot_delay": 0.0}))
    column = run.reference["friction_work"]
    energy = run.metrics["energy"]
    assert column.iloc[-1] == energy["reference_friction_work"] > 0.0
    assert (column.diff().dropna() >= 0.0).all()
    # the undamped law of the preset: the reference loses only what friction took
    lost = energy["initial"] - energy["reference_final"]
    assert energy["reference_friction_work"] == pytest.approx(lost, rel=1e-3)
    frictionless = hc.simulate(hc.load_scenario("oblique-6dof", overrides={"facility.robot_delay": 0.0}))
    assert frictionless.metrics["energy"]["reference_friction_work"] == 0.0
    assert energy["reference_final"] < frictionless.metrics["energy"]["reference_final"]


@pytest.mark.parametrize(
    ("key", "value", "words"),
    [
        ("contact.friction.kinetic", 3, "must be between 0 and 2, got 3"),
        ("contact.friction.static", -0.1, "must be between 0 and 2, got -0.1"),
        ("contact.friction.stick_velocity", 0, "must be between 1e-6 and 1, got 0"),
        ("contact.friction.stribeck_velocity", 2, "must be between 1e-6 and 1, got 2"),
    ],
)
def test_a_coefficient_out_of_range_names_its_key_and_range(key, value, words):
    with pytest.raises(ScenarioError, match=rf"{key}: {words}"):
        hc.load_scenario("paper-table1", overrides={key: value}).resolve()


def test_a_static_coefficient_below_the_kinetic_one_is_one_line_exit_2(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "hilcontact", "run", "paper-table1", "--set", "contact.friction.kinetic=0.3",
         "--set", "contact.friction.static=0.2", "--no-plots", "--out", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "error: contact.friction.static: the static coefficient (0.2) must not be below the kinetic one (0.3)"
    ]
    assert not out.exists()
