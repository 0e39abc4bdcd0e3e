#!/usr/bin/env python3
"""Where a compensator's error on a frictional contact comes from: per collision, against the
reference.

For each collision matched to a reference collision (the normal n: the direction of the
reference's normal impulse, its contact force less its friction), one row:

- ``dv_n``, ``dv_t``: the rebound velocity error along n and across it, % of |v_ref|;
- ``J_n``, ``J_t``: the normal and tangential impulse errors of the wrench the virtual dynamics
  felt, % of the reference's (J_t against max(|J_t,ref|, 0.01 |J_n,ref|), as the metrics);
- ``μ app``: the friction ratio the virtual dynamics felt, Σ|F_t| / ΣF_n (applied), against
  ``μ ref`` (the reference's) and ``μ rob`` (the robot's physical contact);
- ``lag°``: the mean angle (weighted by |F_t|) between the applied tangential force and the
  virtual tip's sliding velocity (0: the friction acts along the virtual sliding), and
  ``rob°`` the same against the robot's sliding;
- ``W_f``: the work of the applied tangential force on the virtual tip's sliding (J, positive:
  dissipated), against the reference's friction work over its collision;
- ``W_n``: the net work of the applied normal force on the virtual tip (J, negative: energy
  given to the servicer) against the reference's.

    python scripts/friction_diagnose.py                       # oblique-6dof μ 0.1 and 0.3, pida
    python scripts/friction_diagnose.py --scene rod-in-frame --kind pida --delay 0.02

Scenes: the preset names, or the labels of scripts/friction_tables.py (``oblique-6dof μ 0.1``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

import hilcontact as hc

sys.path.insert(0, str(Path(__file__).resolve().parent))
import friction_tables  # noqa: E402


def _vec(frame: Any, name: str, rows: Any = slice(None)) -> np.ndarray:
    return np.stack([frame[f"{name}_{a}"].to_numpy()[rows] for a in "xyz"], axis=1)


def _scene(name: str) -> Any:
    for label, raw in friction_tables.scenes():
        if label == name:
            return raw
    return name


def diagnose(scene: Any, kind: str, delay: float) -> list[dict[str, float]]:
    """The rows of one run (see the module doc)."""
    scenario = hc.load_scenario(
        scene, {**friction_tables.FACILITY, "facility.robot_delay": delay, "compensator.kind": kind}
    )
    run = hc.simulate(scenario)
    m, ts, ref = run.metrics, run.timeseries, run.reference
    t_h, t_r = ts["time"].to_numpy(), ref["time"].to_numpy()
    dt_h, dt_r = t_h[1] - t_h[0], t_r[1] - t_r[0]
    references = {c["index"]: c for c in m.get("reference_collisions") or []}
    rows = []
    for c in m.get("collisions") or []:
        r = references.get(c.get("reference"))
        if r is None or not c.get("complete"):
            continue
        h = (t_h >= c["start"] - 0.005) & (t_h <= c["end"] + 0.005)
        q = (t_r >= r["start"] - 0.005) & (t_r <= r["end"] + 0.005)
        f_r, ff_r = _vec(ref, "contact_force", q), _vec(ref, "friction_force", q)
        j_nr = (f_r - ff_r).sum(axis=0) * dt_r
        n = j_nr / np.linalg.norm(j_nr)
        f_h = -_vec(ts, "applied_force", h)  # on the rod
        v_h = _vec(ts, "tip_velocity", h)
        v_a = _vec(ts, "actual_tip_velocity", h)
        ff_rob = _vec(ts, "friction_force", h)
        f_phys = _vec(ts, "contact_force", h)
        fn_h = f_h @ n
        ft_h = f_h - np.outer(fn_h, n)
        j_h, j_r = f_h.sum(axis=0) * dt_h, f_r.sum(axis=0) * dt_r
        jn_h, jn_r = j_h @ n, j_r @ n
        jt_h, jt_r = j_h - jn_h * n, j_r - jn_r * n
        vt_h = v_h - np.outer(v_h @ n, n)
        vt_a = v_a - np.outer(v_a @ n, n)

        def angle(force_t: np.ndarray, slide: np.ndarray) -> float:
            w = np.linalg.norm(force_t, axis=1)
            s = np.linalg.norm(slide, axis=1)
            ok = (w > 1e-6) & (s > 1e-3)
            if not ok.any():
                return float("nan")
            # friction on the rod opposes its sliding
            cos = np.einsum("ij,ij->i", -force_t[ok], slide[ok]) / (w[ok] * s[ok])
            return float(np.degrees(np.average(np.arccos(np.clip(cos, -1, 1)), weights=w[ok])))

        fn_r = (f_r - ff_r) @ n
        fn_p = (f_phys - ff_rob) @ n
        w_r = ref["friction_work"].to_numpy()
        row = {
            "#": c["index"] if "index" in c else len(rows) + 1,
            "dv_n": float("nan"),
            "dv_t": float("nan"),
            "J_n": 100 * (jn_h - jn_r) / abs(jn_r),
            "J_t": 100 * np.linalg.norm(jt_h - jt_r) / max(np.linalg.norm(jt_r), 0.01 * abs(jn_r)),
            "μ app": np.linalg.norm(ft_h, axis=1).sum() / max(fn_h.clip(0).sum(), 1e-9),
            "μ ref": np.linalg.norm(ff_r, axis=1).sum() / max(fn_r.clip(0).sum(), 1e-9),
            "μ rob": np.linalg.norm(ff_rob, axis=1).sum() / max(fn_p.clip(0).sum(), 1e-9),
            "lag°": angle(ft_h, vt_h),
            "rob°": angle(ft_h, vt_a),
            "W_f": float(np.sum(np.einsum("ij,ij->i", -ft_h, vt_h)) * dt_h),
            "W_f ref": float(w_r[q][-1] - w_r[q][0]),
            "W_n": float(np.sum(fn_h * (v_h @ n)) * dt_h),
            "W_n ref": float(np.sum(fn_r * (_vec(ref, "tip_velocity", q) @ n)) * dt_r),
        }
        if c.get("rebound_velocity") is not None and r.get("rebound_velocity") is not None:
            dv = np.asarray(c["rebound_velocity"]) - np.asarray(r["rebound_velocity"])
            scale = np.linalg.norm(r["rebound_velocity"])
            row["dv_n"] = 100 * float(dv @ n) / scale
            row["dv_t"] = 100 * float(np.linalg.norm(dv - (dv @ n) * n)) / scale
        rows.append(row)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", action="append", help="preset or friction_tables label")
    parser.add_argument("--kind", default="pida")
    parser.add_argument("--delay", type=float, action="append")
    args = parser.parse_args()
    for scene in args.scene or ["oblique-6dof μ 0.1", "oblique-6dof μ 0.3"]:
        for delay in args.delay or [0.01, 0.02]:
            rows = diagnose(_scene(scene), args.kind, delay)
            print(f"### {scene}, {args.kind}, {delay * 1e3:.0f} ms")
            if not rows:
                print("(no collision compared)\n")
                continue
            keys = list(rows[0])
            print("| " + " | ".join(keys) + " |")
            print("|" + "---|" * len(keys))
            for row in rows:
                print("| " + " | ".join(f"{row[k]:.3g}" if isinstance(row[k], float) else str(row[k]) for k in keys) + " |")
            print(flush=True)


if __name__ == "__main__":
    main()
