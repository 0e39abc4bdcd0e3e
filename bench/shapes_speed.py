"""The cost of collision shapes (issue 21's speed target): a 6 s `rod-in-frame` run at 1 ms
(a cylinder rod against four boxes, friction) and a `probe-drogue` run (a capsule against a
384-triangle mesh) against today's `paper-table1` run, each as it is; medians of `--repeat`
runs of `hilcontact.simulate` (time series included), the presets taken in turn in every round
(so that a change of the machine's load weighs on all three alike), with the load average
printed, and the fastest run of each (on a busy machine the least disturbed one). The target:
rod-in-frame at most 3x paper-table1 (medians).

    python bench/shapes_speed.py [--repeat 7]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import hilcontact as hc


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    names = ["paper-table1", "rod-in-frame", "probe-drogue"]
    scenarios = {name: hc.load_scenario(name) for name in names}
    for s in scenarios.values():
        hc.simulate(s)  # warm up
    load = os.getloadavg()[0]
    times: dict[str, list[float]] = {name: [] for name in names}
    for _ in range(args.repeat):
        for name, s in scenarios.items():
            start = time.perf_counter()
            hc.simulate(s)
            times[name].append(time.perf_counter() - start)
    print(f"load average {load:.1f} before, {os.getloadavg()[0]:.1f} after ({os.cpu_count()} cores)")
    base = statistics.median(times[names[0]])
    fastest = min(times[names[0]])
    for name, s in scenarios.items():
        t = statistics.median(times[name])
        m = min(times[name])
        simulated = s.simulation.duration
        print(
            f"{name:14s} {simulated:4.1f} s simulated: median {t * 1e3:7.1f} ms  ({t / base:4.2f}x paper-table1), "
            f"fastest {m * 1e3:7.1f} ms ({m / fastest:4.2f}x)"
        )


if __name__ == "__main__":
    main()
