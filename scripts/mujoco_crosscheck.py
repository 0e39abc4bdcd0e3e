"""Print the MuJoCo cross-check table of docs/mujoco.md: every case of
``hilcontact.mujoco.crosscheck.CASES`` against the ideal reference, at each MuJoCo step.

    python scripts/mujoco_crosscheck.py                       # steps 1e-4 s
    python scripts/mujoco_crosscheck.py --steps 1e-4,3e-5,1e-5 --cases "oblique mu=0.3"
    python scripts/mujoco_crosscheck.py --constant-friction   # MuJoCo's own friction regularisation
    python scripts/mujoco_crosscheck.py --no-sliding          # the slope following F_n only
    python scripts/mujoco_crosscheck.py --cases probe-drogue --duration 6

Needs the mujoco package (pip install 'hilcontact[mujoco]').
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

from hilcontact.mujoco import crosscheck as cc
from hilcontact.mujoco.mjcf import ContactMatch


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", default="1e-4", help="MuJoCo steps, s, comma-separated [default: 1e-4]")
    parser.add_argument("--cases", default="", help="case names, comma-separated [default: all]")
    parser.add_argument("--impedance", type=float, default=ContactMatch().impedance,
                        help=f"MuJoCo's constant impedance d [default: {ContactMatch().impedance}]")
    parser.add_argument("--duration", type=float, default=None,
                        help="simulation.duration of every case, s [default: each case's own]")
    parser.add_argument("--constant-friction", action="store_true",
                        help="MuJoCo's friction with a constant viscous coefficient below the cone (not following F_n)")
    parser.add_argument("--no-sliding", action="store_true",
                        help="the viscous coefficient follows F_n only, not the sliding speed (Coulomb at the cone)")
    args = parser.parse_args(argv)
    steps = tuple(float(x) for x in args.steps.split(","))
    names = [n.strip() for n in args.cases.split(",") if n.strip()]
    unknown = [n for n in names if n not in {c.name for c in cc.CASES}]
    if unknown:
        print(f"error: --cases: unknown {unknown}; cases: {[c.name for c in cc.CASES]}", file=sys.stderr)
        return 2
    cases = tuple(c for c in cc.CASES if not names or c.name in names)
    if args.duration is not None:
        if not 0.0 < args.duration <= 60.0:
            print(f"error: --duration: expected 0 to 60 s, got {args.duration}", file=sys.stderr)
            return 2
        cases = tuple(replace(c, overrides={**c.overrides, "simulation.duration": args.duration}) for c in cases)
    match = ContactMatch(impedance=args.impedance, track_friction=not args.constant_friction,
                         track_sliding=not args.constant_friction and not args.no_sliding)
    start = time.perf_counter()
    cc.table(cases, steps, match, echo=print)
    print(f"\n{len(cases)} case(s), steps {', '.join(f'{h:g}' for h in steps)} s, impedance {match.impedance:g}, "
          f"friction {'constant below the cone' if args.constant_friction else 'following F_n' if args.no_sliding else 'following F_n and the sliding speed'}: "
          f"{time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
