#!/usr/bin/env python3
"""The "friction and corners" tables of docs/compensators/*.md, measured by running them.

For each scene (oblique-6dof with μ = 0.1 and 0.3, a corner: the rod tip driven into the
edge of two walls, and random oblique frictional scenes from a fixed seed) and each
compensator, at 10 and 20 ms robot delay with 0.2 N sensor noise and 5 ms sensor delay, one
row: the reference collisions lost and the extra ones, the worst rebound velocity error and
CoF (from metrics.json), the worst tangential impulse error (computed here: the wrench the
virtual dynamics felt, integrated over the collision, its part across the contacted wall's
normal, against the reference's), the worst excess of the energy after a collision over the
reference's (%), the worst gain of energy over a collision (after it against before it, %:
positive breaks passivity), and the run's status.

    python scripts/friction_tables.py                 # print every table
    python scripts/friction_tables.py --kind pida     # one compensator
    python scripts/friction_tables.py --write         # update the pages' tables
    python scripts/friction_tables.py --kind model-mediated --delays 0.04   # other delays

model-mediated runs at 40, 80 and 120 ms, each scene without priors, with its walls as prior
geometry, and with its walls and law as a calibration and its friction coefficient as
``prior_friction``, and adds the worst over the collisions its model rendered (each surface's second
contact on, or the first with a prior wall and a law known), the metrics' own per-collision
errors. It also runs the presets with shapes (``rod-in-frame``, ``probe-drogue``) without priors
and with their shapes as prior geometry (``prior_shapes``): the law unknown (``geometry``), and
the scenario's law and friction known (``geometry-and-law``); there the tangential impulse is taken across the reference's normal
impulse (no walls).
model-mediated's rows add the same model-rendered collisions (matched or not) against their
local (restarted) references, the metrics' ``local_*`` errors (docs/model.md "Metrics": each
contact read from the state it began in; never the verdict).

A page's table is the region between ``<!-- friction-tables: KIND -->`` and
``<!-- /friction-tables -->`` of docs/compensators/KIND.md.

Every run is deterministic (fixed seeds).
"""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

import hilcontact as hc

#: The facility of the tables: 0.2 N noise, 5 ms sensor delay.
FACILITY = {"facility.sensor_noise": 0.2, "facility.sensor_delay": 0.005}
DELAYS = (0.01, 0.02)
KINDS = ("none", "pic", "dac", "pida", "tdpa-impedance", "tdpa-admittance", "model-mediated")
#: Delays per compensator where they differ from DELAYS: model-mediated is meant for long ones.
KIND_DELAYS = {"model-mediated": (0.04, 0.08, 0.12)}


def _oblique(mu: float) -> dict[str, Any]:
    raw = hc.load_scenario("oblique-6dof").to_dict()
    raw["contact"]["friction"] = {"kinetic": mu}
    return raw


def _corner(mu: float) -> dict[str, Any]:
    """The rod tip driven into an inside corner: two walls 30° either side of −x meeting in an
    edge along z straight ahead of the tip; the servicer drifts towards +y, so the tip slides
    along one wall into the edge and presses both."""
    raw = _oblique(mu)
    c, s = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    raw["walls"] = [
        {"name": "corner-a", "point": [0.010, 0.10, 0.05], "normal": [-c, -s, 0.0]},
        {"name": "corner-b", "point": [0.010, 0.10, 0.05], "normal": [-c, s, 0.0]},
        {"name": "rear", "point": [-0.010, 0.0, 0.0], "normal": [1.0, 0.0, 0.0]},
    ]
    raw["servicer"]["velocity"] = [0.02, 0.004, 0.0]
    raw["servicer"]["angular_velocity"] = [0.0, 0.0, 0.0]
    raw["simulation"]["duration"] = 4.0
    return raw


def _random(seed: int, count: int) -> list[tuple[str, dict[str, Any]]]:
    rng = np.random.default_rng(seed)
    scenes = []
    for i in range(count):
        mu = float(rng.uniform(0.1, 0.3))
        yaw, pitch = np.radians(rng.uniform(15.0, 35.0)), np.radians(rng.uniform(-10.0, 10.0))
        raw = _oblique(mu)
        raw["walls"][0]["normal"] = [-math.cos(yaw) * math.cos(pitch), -math.sin(yaw), math.sin(pitch)]
        raw["servicer"]["mass"] = float(rng.uniform(200.0, 400.0))
        raw["servicer"]["velocity"] = [float(rng.uniform(0.015, 0.03)), 0.003, -0.001]
        scenes.append((f"random {i + 1} (μ {mu:.2f}, {math.degrees(yaw):.0f}°)", raw))
    return scenes


def scenes() -> list[tuple[str, dict[str, Any]]]:
    """(label, raw scenario) of every scene."""
    return [
        ("oblique-6dof μ 0.1", _oblique(0.1)),
        ("oblique-6dof μ 0.3", _oblique(0.3)),
        ("corner μ 0.2", _corner(0.2)),
        *_random(22, 3),
    ]


def _vec(frame: Any, name: str, rows: Any) -> np.ndarray:
    return np.stack([frame[f"{name}_{a}"].to_numpy()[rows] for a in "xyz"], axis=1)


def _calibration(raw: dict[str, Any], delay: float) -> dict[str, Any]:
    """A calibration of the scene's walls and law (exact, small stated uncertainties), as
    ``hilcontact calibrate`` would write it."""
    contact = raw["contact"]
    return {
        "walls": [
            {"name": w["name"], "point": w["point"], "normal": w["normal"], "offset_sigma": 1e-5,
             "angle_sigma": 0.02, "radius": 0.02, "probes": 9, "rms": 0.2}
            for w in raw["walls"]
        ],
        "law": {"model": "linear", "stiffness": contact["stiffness"], "damping": contact["damping"],
                "exponent": 1.0, "stiffness_sigma": 0.005 * contact["stiffness"], "damping_sigma": 5.0,
                "exponent_sigma": 0.0},
        "robot": {"delay": delay},
    }


#: The presets with shapes, for model-mediated's shapes prior.
SHAPE_PRESETS = ("rod-in-frame", "probe-drogue")


def measure(raw: dict[str, Any], kind: str, delay: float, prior: str = "") -> dict[str, Any]:
    """One run's row (see the module doc); ``prior`` (model-mediated): ``"walls"``, the scene's
    walls as its prior geometry (``compensator.prior_walls``); ``"all"``, its walls and law as
    a calibration and its friction coefficient as ``prior_friction``; ``"shapes"``, its shapes
    as prior geometry (``prior_shapes = "geometry"``); ``"shapes-law"``, its shapes, law and
    friction (``prior_shapes = "geometry-and-law"``)."""
    compensator: dict[str, Any] = {"kind": kind}
    if prior == "walls":
        compensator["prior_walls"] = raw["walls"]
    elif prior == "all":
        compensator["calibration"] = _calibration(raw, delay)
        compensator["prior_friction"] = raw["contact"]["friction"]["kinetic"]
    elif prior == "shapes":
        compensator["prior_shapes"] = "geometry"
    elif prior == "shapes-law":
        compensator["prior_shapes"] = "geometry-and-law"
    raw = {**raw, "compensator": compensator}
    local = {"metrics.local_references": True} if kind == "model-mediated" else {}
    scenario = hc.load_scenario(raw, {**FACILITY, "facility.robot_delay": delay, **local})
    run = hc.simulate(scenario)
    m = run.metrics
    ts, ref = run.timeseries, run.reference
    normals = [np.asarray(w["normal"], dtype=float) / np.linalg.norm(w["normal"]) for w in raw.get("walls") or []]
    references = {c["index"]: c for c in m.get("reference_collisions") or []}
    t_h, t_r = ts["time"].to_numpy(), ref["time"].to_numpy()
    dt = float(raw["simulation"]["period"])
    tangential, energy, gain = [], [], []
    for c in m.get("collisions") or []:
        r = references.get(c.get("reference"))
        if r is None or not c.get("complete"):
            continue
        rows_h = (t_h >= c["start"] - 0.005) & (t_h <= c["end"] + 0.005)
        rows_r = (t_r >= r["start"] - 0.005) & (t_r <= r["end"] + 0.005)
        # the wrench the virtual dynamics felt (on the frame) and the reference's on the rod
        j_h = -_vec(ts, "applied_force", rows_h).sum(axis=0) * dt
        j_r = _vec(ref, "contact_force", rows_r).sum(axis=0) * (t_r[1] - t_r[0])
        if normals:
            n = max(normals, key=lambda n: abs(float(j_r @ n)))
        else:
            # shapes, no walls: across the reference's normal impulse
            j_n = j_r - _vec(ref, "friction_force", rows_r).sum(axis=0) * (t_r[1] - t_r[0])
            n = j_n / np.linalg.norm(j_n)
        t_hil, t_ref = j_h - (j_h @ n) * n, j_r - (j_r @ n) * n
        if np.linalg.norm(t_ref) > 1e-3 * np.linalg.norm(j_r):
            tangential.append(float(np.linalg.norm(t_hil - t_ref) / np.linalg.norm(t_ref)))
        if c.get("rebound_time") is not None:
            after = c["rebound_time"]
            e_h = float(np.interp(after, t_h, ts["energy"].to_numpy()))
            # the reference's energy in the free flight after its collision
            nxt = min((x["start"] for x in references.values() if x["start"] > r["end"]), default=t_r[-1])
            e_r = float(np.interp(0.5 * (r["end"] + nxt), t_r, ref["energy"].to_numpy()))
            energy.append((e_h - e_r) / e_r)
            # passivity: the energy after the exchange against the energy before it
            e_before = float(np.interp(c["start"] - 0.01, t_h, ts["energy"].to_numpy()))
            gain.append((e_h - e_before) / e_before)
    s = m.get("summary") or {}
    # the collisions the identified model rendered (model-mediated: each surface's second
    # contact on; the first is pida's)
    modelled = [c for c in m.get("collisions") or [] if c.get("rendering") == "model" and c.get("reference") is not None]

    def worst(key: str) -> float:
        values = [c[key] for c in modelled if c.get(key) is not None]
        return max(values) if values else float("nan")

    # the same collisions against their local (restarted) references, matched or not
    # (docs/model.md "Metrics": each contact read on its own; never the verdict)
    local = [c for c in m.get("collisions") or [] if c.get("rendering") == "model" and c.get("local_velocity_error") is not None]

    def worst_local(key: str) -> float:
        values = [c[key] for c in local if c.get(key) is not None]
        return max(values) if values else float("nan")

    return {
        "modelled": len(modelled),
        "model_velocity_error": worst("velocity_error"),
        "model_cof": worst("cof"),
        "model_tangential": worst("tangential_impulse_error"),
        "local_modelled": len(local),
        "local_velocity_error": worst_local("local_velocity_error"),
        "local_cof": worst_local("local_cof"),
        "local_tangential": worst_local("local_tangential_impulse_error"),
        "status": m.get("status"),
        "lost": len(m.get("lost_collisions") or []),
        "extra": len(m.get("extra_collisions") or []),
        "velocity_error": s.get("worst_velocity_error"),
        "cof": s.get("worst_cof"),
        "tangential": max(tangential) if tangential else float("nan"),
        "energy": max(energy) if energy else float("nan"),
        "gain": max(gain) if gain else float("nan"),
    }


def _pct(x: Any) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.1f}"


def _num(x: Any) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.3f}"


HEADER = ("| scene | delay | lost/extra | v err % | CoF | tangential J err % | energy excess % "
          "| energy gain % | status |")


#: Extra columns of a model-based compensator: the worst over the collisions the model rendered
#: (their count; rebound velocity vector error, CoF and tangential impulse error, the metrics'
#: own definitions).
MODEL_HEADER = " model-rendered | its v err % | its CoF | its J_t err % |"
#: Extra columns of model-mediated: the same collisions (matched or not) against their local
#: references (docs/model.md "Metrics", ``local_*``: each contact read from the state it began
#: in; never the verdict): their count, the worst local rebound velocity error, CoF and
#: tangential impulse error.
LOCAL_HEADER = " local: model-rendered | local v err % | local CoF | local J_t err % |"


def table(kind: str, delays: tuple[float, ...] | None = None) -> list[str]:
    """The Markdown table of one compensator."""
    model = kind == "model-mediated"
    header = HEADER + MODEL_HEADER + LOCAL_HEADER if model else HEADER
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    variants = [(label, raw, "") for label, raw in scenes()]
    if model:
        variants += [(f"{label}, prior walls", raw, "walls") for label, raw in scenes()]
        variants += [(f"{label}, calibrated, prior μ", raw, "all") for label, raw in scenes()]
        for name in SHAPE_PRESETS:
            raw = hc.load_scenario(name).to_dict()
            variants += [
                (name, raw, ""),
                (f"{name}, prior shapes", raw, "shapes"),
                (f"{name}, prior shapes and law", raw, "shapes-law"),
            ]
    for label, raw, prior in variants:
        for delay in delays or KIND_DELAYS.get(kind, DELAYS):
            row = measure(raw, kind, delay, prior)
            line = (
                f"| {label} | {delay * 1e3:.0f} ms | {row['lost']}/{row['extra']} | {_pct(row['velocity_error'])} | "
                f"{_num(row['cof'])} | {_pct(row['tangential'])} | {_pct(row['energy'])} | {_pct(row['gain'])} | "
                f"{row['status']} |"
            )
            if model:
                line += (
                    f" {row['modelled']} | {_pct(row['model_velocity_error'])} | {_num(row['model_cof'])} | "
                    f"{_pct(row['model_tangential'])} |"
                )
                line += (
                    f" {row['local_modelled']} | {_pct(row['local_velocity_error'])} | {_num(row['local_cof'])} | "
                    f"{_pct(row['local_tangential'])} |"
                )
            lines.append(line)
    return lines


ROOT = Path(__file__).resolve().parents[1]


def write(kind: str, lines: list[str]) -> None:
    """Replaces the table region of docs/compensators/KIND.md."""
    page = ROOT / "docs" / "compensators" / f"{kind}.md"
    text = page.read_text()
    pattern = re.compile(rf"(<!-- friction-tables: {re.escape(kind)} -->\n).*?(<!-- /friction-tables -->)", re.S)
    if not pattern.search(text):
        raise SystemExit(f"{page}: no friction-tables region for {kind}")
    page.write_text(pattern.sub(lambda m: m.group(1) + "\n".join(lines) + "\n" + m.group(2), text))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kind", action="append", choices=KINDS, help="compensator(s) (default: all)")
    parser.add_argument("--write", action="store_true", help="update the docs pages")
    parser.add_argument("--delays", help="robot delays, s, comma-separated (default: 0.01,0.02; model-mediated 0.04,0.08,0.12)")
    args = parser.parse_args()
    try:
        delays = tuple(float(x) for x in args.delays.split(",")) if args.delays else None
    except ValueError:
        parser.error(f"--delays: not a list of numbers: {args.delays!r}")
    if delays is not None and args.write:
        parser.error("--write takes the default delays only")
    for kind in args.kind or KINDS:
        lines = table(kind, delays)
        print(f"### {kind}")
        print("\n".join(lines))
        print(flush=True)
        if args.write:
            write(kind, lines)


if __name__ == "__main__":
    main()
