"""A sweep over robot delay and contact stiffness, then the stability map: up to which delay
each compensator stays faithful, per contact frequency.

    python examples/sweep_stability_map.py [OUT_DIR] [--points N]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import hilcontact as hc


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="sweeps/my-sweep", help="output folder")
    parser.add_argument("--points", type=int, default=12, help="robot delays swept")
    args = parser.parse_args()

    rows = hc.sweep(
        "paper-table1",
        {
            "facility.robot_delay": f"0.002:0.06:{args.points}",  # s, both ends included
            "contact.stiffness": [44_000.0, 176_275.0],            # N/m: 2 and 4 Hz contacts
        },
        compensators="none,pida",
        out=args.out,  # results.parquet, kept up to date; resume=True continues a stopped sweep
        progress=lambda done, total: print(f"\r{done}/{total} runs", end="", flush=True),
    )
    print()
    stability = hc.stability_map(rows)
    print("largest faithful robot delay (s) per contact frequency (Hz):")
    print(stability.max_faithful_delay().to_string(float_format=lambda v: f"{v:.3f}"))
    folder = stability.save(Path(args.out) / "stability")
    print(f"stability map figures and tables in {folder}/")


if __name__ == "__main__":
    main()
