"""The cost of collision shapes (issue 21's speed target): a 6 s `rod-in-frame` run at 1 ms
(a cylinder rod against four boxes, friction) and a `probe-drogue` run (a capsule against a
384-triangle mesh) against today's `paper-table1` run, each as it is, back to back; medians of
`--repeat` runs of `hilcontact.simulate` (time series included). The target: rod-in-frame at
most 3x paper-table1.

    python bench/shapes_speed.py [--repeat 7]
"""

from __future__ import annotations

import argparse
import statistics
import time

import hilcontact as hc


def median_seconds(scenario: hc.Scenario, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        hc.simulate(scenario)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    names = ["paper-table1", "rod-in-frame", "probe-drogue"]
    scenarios = {name: hc.load_scenario(name) for name in names}
    for s in scenarios.values():
        hc.simulate(s)  # warm up
    base = None
    for name, s in scenarios.items():
        t = median_seconds(s, args.repeat)
        base = base or t
        simulated = s.simulation.duration
        print(f"{name:14s} {simulated:4.1f} s simulated: median {t * 1e3:7.1f} ms  ({t / base:4.2f}x paper-table1)")


if __name__ == "__main__":
    main()
