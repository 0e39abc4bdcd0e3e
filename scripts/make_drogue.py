"""Writes the drogue of the `probe-drogue` preset as an OBJ mesh
(python/hilcontact/scenarios/probe-drogue-cone.obj).

The drogue: a cone of 30 degrees half-angle opening toward -x, from a 100 mm mouth radius at
x = 0 down to a 20 mm throat, then a 50 mm long throat tube of 20 mm radius (dimensions
chosen at the scale of a small probe-drogue docking mechanism; the probe is 20 mm wide). The
surface is open at both ends (a manifold with boundary), 96 facets around: a facet's chord
departs from the true cone by at most R (1 - cos(pi/96)) = 0.05 mm at the mouth.

    python scripts/make_drogue.py
"""

from __future__ import annotations

import math
from pathlib import Path

SEGMENTS = 96
MOUTH_RADIUS = 0.100  # m
THROAT_RADIUS = 0.020  # m
HALF_ANGLE = math.radians(30.0)
THROAT_LENGTH = 0.050  # m


def rings() -> list[tuple[float, float]]:
    """(x, radius) of each ring of vertices, m."""
    cone = (MOUTH_RADIUS - THROAT_RADIUS) / math.tan(HALF_ANGLE)
    return [(0.0, MOUTH_RADIUS), (cone, THROAT_RADIUS), (cone + THROAT_LENGTH, THROAT_RADIUS)]


def obj_text() -> str:
    lines = [f"# probe-drogue cone: written by scripts/make_drogue.py ({SEGMENTS} facets around; metres)"]
    for x, r in rings():
        for k in range(SEGMENTS):
            a = 2.0 * math.pi * k / SEGMENTS
            lines.append(f"v {x:.9f} {r * math.cos(a):.9f} {r * math.sin(a):.9f}")
    for i in range(len(rings()) - 1):
        for k in range(SEGMENTS):
            a, b = i * SEGMENTS + k + 1, i * SEGMENTS + (k + 1) % SEGMENTS + 1  # OBJ indices from 1
            c, d = a + SEGMENTS, b + SEGMENTS
            lines.append(f"f {a} {c} {d}")
            lines.append(f"f {a} {d} {b}")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    out = Path(__file__).resolve().parent.parent / "python" / "hilcontact" / "scenarios" / "probe-drogue-cone.obj"
    out.write_text(obj_text(), encoding="utf-8")
    print(f"wrote {out}")
