"""What a compensator written in Python costs per tick (docs/compensators/python.md quotes it).

    python bench/python_compensator.py [--repeats 5] [--preset paper-table1]

Runs the preset (5.5 s simulated at 1 kHz: 5501 ticks, its ideal reference included) with
the shipped `none` and `pic` (Rust) and with the Python pass-through and the 30-line Python
PIC of examples/compensators, and prints the median wall time of each and the extra time per
tick of the Python ones over their Rust counterpart, µs.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import hilcontact as hc

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "compensators"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--preset", default="paper-table1")
    args = parser.parse_args()
    cases = {
        "none (Rust)": ("none", None),
        "pass-through (Python)": ("none", f"{EXAMPLES / 'pass_through.py'}:PassThrough"),
        "pic (Rust)": ("pic", None),
        "PythonPic (Python)": ("pic", f"{EXAMPLES / 'pic.py'}:PythonPic"),
    }
    times: dict[str, float] = {}
    ticks = 0
    for name, (kind, entry) in cases.items():
        scenario = hc.load_scenario(args.preset, {"compensator.kind": kind})
        samples = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            run = hc.simulate(scenario, compensator=entry)
            samples.append(time.perf_counter() - start)
        ticks = len(run.timeseries)
        times[name] = statistics.median(samples)
        print(f"{name:24s} {times[name] * 1e3:8.1f} ms per run ({ticks} ticks, median of {args.repeats})")
    for python, rust in (("pass-through (Python)", "none (Rust)"), ("PythonPic (Python)", "pic (Rust)")):
        extra = (times[python] - times[rust]) / ticks
        print(f"{python:24s} {extra * 1e6:8.1f} µs per tick more than {rust}")


if __name__ == "__main__":
    main()
