"""`hilcontact identify` on frictional contacts: the friction coefficient per collision, the
normal of a frictional surface (not the leaning force's direction) and the stiffness along it
(issue 22)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import hilcontact as hc
from hilcontact.cli import cli

K_TRUE, C_TRUE = 176275.0, 130.0


def invoke(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args], prog_name="hilcontact")


def _frictional_oblique(mu: float, noise: float):
    overrides = {"compensator.kind": "pida", "contact.damping": C_TRUE, "contact.friction.kinetic": mu,
                 "facility.sensor_noise": noise, "facility.sensor_delay": 0.005 if noise else 0.0,
                 "simulation.duration": 2.0}
    return hc.simulate(hc.load_scenario("oblique-6dof", overrides))


@pytest.mark.parametrize(("mu", "noise", "mu_tol", "k_tol"), [(0.1, 0.0, 0.03, 0.02), (0.25, 0.2, 0.05, 0.05)])
def test_identify_reports_the_friction_coefficient(core, tmp_path, mu, noise, mu_tol, k_tol):
    run = _frictional_oblique(mu, noise)
    folder = tmp_path / "run"
    run.save(folder, plots=False)
    out = tmp_path / "id"
    result = invoke("identify", folder, "--out", out)
    assert result.exit_code == 0, result.output
    assert "μ" in result.output
    collisions = pd.read_csv(out / "collisions.csv")
    front = np.array(run.scenario.to_dict()["walls"][0]["normal"], dtype=float)
    front /= np.linalg.norm(front)
    rows = [c for _, c in collisions.iterrows()
            if float(np.array([c["normal_x"], c["normal_y"], c["normal_z"]]) @ front) > 0.9]
    assert rows, collisions
    for c in rows:
        normal = np.array([c["normal_x"], c["normal_y"], c["normal_z"]])
        angle = math.degrees(math.acos(min(1.0, float(normal @ front))))
        assert bool(c["frictional"]), c.to_dict()
        assert abs(c["friction"] - mu) <= mu_tol, c.to_dict()
        assert abs(c["stiffness"] / K_TRUE - 1) <= k_tol, c.to_dict()
        # the force leans by atan μ (5.7° at 0.1); the identified normal is the wall's
        assert angle < 1.0, angle


def test_a_frictionless_contact_reports_no_friction(core, tmp_path):
    run = _frictional_oblique(0.0, 0.0)
    folder = tmp_path / "run"
    run.save(folder, plots=False)
    out = tmp_path / "id"
    assert invoke("identify", folder, "--out", out).exit_code == 0
    collisions = pd.read_csv(out / "collisions.csv")
    assert len(collisions) >= 1
    assert not collisions["frictional"].astype(bool).any()
    assert (collisions["friction"] == 0.0).all()
