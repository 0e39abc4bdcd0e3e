"""Identify a contact from a recording: stiffness, damping and the wall, per collision.

The "recording" here is a CSV exported from a simulated run whose contact is known (an
oblique wall, 130 N s/m of damping), so the script can print how close the identification
comes; replace it with your own log (columns: README, "Your own data").

    python examples/identify_a_recording.py [WORK_DIR]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

import hilcontact as hc
from hilcontact.recording import identify, read_recording


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("work", nargs="?", default="runs/identify-example", help="folder for the recording")
    args = parser.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)

    # 1. a recording with a known contact: the oblique 6-DOF preset with damping, as a CSV log
    truth = hc.load_scenario("oblique-6dof", {"contact.damping": 130.0, "compensator.kind": "pida"})
    run = hc.simulate(truth)
    log = work / "log.csv"
    run.timeseries.to_csv(log, index=False)

    # 2. identify it (the scenario gives the sensor's pose on the rod; the contact is unknown)
    recording = read_recording(log, scenario="oblique-6dof")
    _, collisions = identify(recording)

    # 3. compare with the truth: each collision against the wall whose normal is nearest
    walls = [(w.name, np.asarray(w.point), np.asarray(w.normal) / np.linalg.norm(w.normal)) for w in truth.walls]
    for _, c in collisions.iterrows():
        found = np.array([c["normal_x"], c["normal_y"], c["normal_z"]])
        name, point, normal = max(walls, key=lambda w: float(found @ w[2]))
        angle = math.degrees(math.acos(min(1.0, float(found @ normal))))
        offset = float((np.array([c["point_x"], c["point_y"], c["point_z"]]) - point) @ normal)
        print(
            f"collision {int(c['index'])} (wall {name!r}): k = {c['stiffness'] / 1e3:.2f} ± {c['stiffness_std'] / 1e3:.2f} N/mm "
            f"(true {truth.contact.stiffness / 1e3:.2f}), c = {c['damping']:.1f} ± {c['damping_std']:.1f} N·s/m "
            f"(true {truth.contact.damping:g}), normal off by {angle:.3f}°, plane off by {offset * 1e3:.4f} mm"
        )


if __name__ == "__main__":
    main()
