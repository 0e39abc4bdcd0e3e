"""Issue 23's targets with a calibration (scripts/calibration_targets.py), a representative
subset: `hilcontact calibrate --simulate` on the honest facility (hardware 0.5 mm and 0.5° off,
7 % stiffer, robot repeatability 0.03 mm, 0.2 N noise, 5 ms sensor delay), then model-mediated
with the file renders every collision, the first included, within the targets; a wrong
calibration's first contact stays within CoF 1.3 and gains no energy.

The rows the table misses (docs/calibration.md, "Measured, simulated") are not asserted here:
the undamped paper-table1 and oblique-6dof's rear wall (the robot's unreported repeatability
error against a shallow contact: the same with an exact calibration) and Hunt-Crossley (its
calibrated law)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "calibration_targets.py"


def targets():
    spec = importlib.util.spec_from_file_location("calibration_targets", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


CT = targets()
CASES = {(c.scene, c.contact): c for c in CT.CASES}


@pytest.mark.parametrize(
    ("scene", "contact", "delay"),
    [
        ("paper-exp-1.93hz", "preset", 0.04),
        ("paper-exp-2.64hz", "preset", 0.08),
        ("paper-table1", "damped ζ 0.1", 0.12),
    ],
)
def test_a_calibration_renders_every_collision_within_the_targets(tmp_path: Path, scene: str, contact: str,
                                                                   delay: float):
    case = CASES[(scene, contact)]
    row = CT.measure(case, delay, tmp_path)
    assert len(row.collisions) >= 3, row
    for c in row.collisions:
        assert abs(c["cov"] - 1) <= CT.COV_LIMIT, CT.table([row])
        assert c["cof"] <= case.cof_limit, CT.table([row])
        assert c["rendering"] == "model", CT.table([row])
    assert row.ok()


def test_a_wrong_calibration_is_passive_and_its_first_contact_bounded(tmp_path: Path):
    row = CT.measure(CASES[("paper-table1", "undamped")], 0.04, tmp_path, wrong_calibration=True)
    assert row.collisions[0]["cof"] <= CT.WRONG_FIRST_COF, CT.table([row])
    assert row.energy_gain <= 1e-3, CT.table([row])
