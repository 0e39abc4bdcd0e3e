"""Compare every compensator on your own scenario.

Starts from a preset, changes what differs on your facility (here: a heavier servicer, a
damped contact, a 40 ms robot and a 2 ms sensor delay), runs each compensator, prints the
summary and saves the comparison (tables and figures) to a folder.

    python examples/compare_your_scenario.py [OUT_DIR] [--duration S]
"""

from __future__ import annotations

import argparse

import hilcontact as hc


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="runs/my-compare", help="output folder")
    parser.add_argument("--duration", type=float, default=5.5, help="simulated time, s")
    args = parser.parse_args()

    # your facility, as overrides of a preset (any key of `hilcontact init my.toml`)
    overrides = {
        "servicer.mass": 600.0,               # kg
        "contact.damping": 200.0,             # N s/m
        "facility.robot_delay": 0.04,         # s
        "facility.sensor_delay": 0.002,       # s
        "simulation.duration": args.duration,  # s
    }
    comparison = hc.compare("paper-table1", "none,pic,pida,tdpa-impedance", overrides)

    summary = comparison.summary[["status", "collisions", "mean_cov", "worst_cov_error", "worst_cof"]]
    print(summary.to_string(float_format=lambda v: f"{v:.3f}"))
    best = summary[summary["status"] == "ok"]["worst_cov_error"].idxmin() if (summary["status"] == "ok").any() else None
    print(f"faithful and closest to the ideal rebound: {best or 'none of them'}")

    folder = comparison.save(args.out, overwrite=False)
    print(f"saved to {folder}/ (comparison.md, comparison.csv, compare_*.png)")


if __name__ == "__main__":
    main()
