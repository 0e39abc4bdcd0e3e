"""Benchmarks of the Python path (docs/performance.md quotes them).

    python bench/python_path.py [--runs 10000] [--skip-sweep] [--json FILE]

1. One ``paper-table1`` run (5.5 s simulated, 1 kHz control, 10 kHz plant, ``pida``, 20 ms
   robot delay) including its ideal reference, from Python on one core: as a sweep runs it
   (``_core.simulate_batch(..., threads=1)``, summary only) and as ``hc.simulate`` runs it
   (time series as the core's columns, made into DataFrames when first read), and
   ``hc.simulate`` with both DataFrames read. Median and p90 of 200 runs (100 for
   ``hc.simulate``), wall time, and the median CPU time of the process (the measure on a
   shared machine).
2. How a run's cost grows with the simulated duration, the control rate and the plant rate
   (plant sub-steps matter with the servo lag on).
3. A sweep of ``--runs`` runs (default 10,000) on all cores with ``hc.sweep``, written to a
   folder: wall time, runs per second, and the resident memory at 10, 50 and 90 % of the
   runs (it must not grow with the number of runs) and after the rows are merged.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import sys
import tempfile
import time

import hilcontact as hc
from hilcontact import _core

BASE = {"compensator.kind": "pida", "facility.robot_delay": 0.02}


def _timings(fn, n: int) -> tuple[list[float], list[float]]:
    """Wall and CPU times (s) of ``n`` calls after one to warm up."""
    fn()  # warm up
    wall, cpu = [], []
    for _ in range(n):
        start, cpu_start = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - cpu_start)
    return wall, cpu


def _stats(timings: tuple[list[float], list[float]]) -> dict[str, float]:
    """Median, p90 and minimum of the wall times, ms, and the median CPU time of the process
    (every thread), ms: on a machine shared with other jobs the wall time measures them too,
    the CPU time much less."""
    samples, cpu = sorted(timings[0]), timings[1]
    return {
        "median_ms": statistics.median(samples) * 1e3,
        "p90_ms": samples[int(0.9 * (len(samples) - 1))] * 1e3,
        "min_ms": samples[0] * 1e3,
        "cpu_median_ms": statistics.median(cpu) * 1e3,
    }


def one_run() -> dict[str, dict[str, float]]:
    scenario = hc.load_scenario("paper-table1", BASE)
    text = scenario.to_json()
    summary = _stats(_timings(lambda: _core.simulate_batch([text], 1), 200))
    full = _stats(_timings(lambda: hc.simulate(scenario), 100))

    def read_tables() -> None:
        run = hc.simulate(scenario)
        run.timeseries, run.reference  # noqa: B018 (the DataFrames are made when first read)

    tables = _stats(_timings(read_tables, 100))
    return {
        "summary only (simulate_batch, 1 thread)": summary,
        "hc.simulate (with time series)": full,
        "hc.simulate, both DataFrames read": tables,
    }


def scaling() -> list[dict[str, float]]:
    rows = []
    cases = [
        ("duration", {"simulation.duration": d}) for d in (2.75, 5.5, 11.0, 22.0)
    ] + [
        ("control rate", {"simulation.period": p, "simulation.duration": 5.5}) for p in (0.002, 0.001, 0.0005, 0.00025)
    ] + [
        ("plant substeps (servo on)", {"facility.servo_frequency": 30.0, "simulation.plant_substeps": n})
        for n in (1, 10, 100)
    ]
    for label, overrides in cases:
        scenario = hc.load_scenario("paper-table1", {**BASE, **overrides})
        text = scenario.to_json()
        stats = _stats(_timings(lambda: _core.simulate_batch([text], 1), 30))
        rows.append({"case": label, **{k: v for k, v in overrides.items()}, **stats})
    return rows


def rss_mib() -> float:
    """Resident memory now (Linux /proc), else the peak so far, MiB."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def sweep(runs: int) -> dict[str, float]:
    # 50 delays x 5 masses x 5 compensators x seeds = runs
    seeds = max(1, runs // (50 * 5 * 5))
    grid = {"facility.robot_delay": "0.001:0.05:50", "servicer.mass": [100, 300, 600, 1200, 2400]}
    kinds = "none,tdpa-impedance,pic,dac,pida"
    total = 50 * 5 * 5 * seeds
    marks: dict[str, float] = {}

    def progress(done: int, all_runs: int) -> None:
        for pct in (10, 50, 90):
            if f"rss_at_{pct}pct_mib" not in marks and done >= pct / 100 * all_runs:
                marks[f"rss_at_{pct}pct_mib"] = rss_mib()

    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        rows = hc.sweep(
            "paper-table1", grid, kinds, seeds=seeds, out=os.path.join(folder, "s"),
            overrides={"facility.sensor_noise": 0.2}, progress=progress,
        )
        elapsed = time.perf_counter() - start
    assert len(rows) == total
    return {
        "runs": total,
        "wall_s": elapsed,
        "runs_per_s": total / elapsed,
        "median_run_wall_ms": float(rows["wall_time"].median() * 1e3),
        **marks,
        "rss_after_merge_mib": rss_mib(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--skip-sweep", action="store_true")
    parser.add_argument("--json", default=None, help="also write the figures to this JSON file")
    args = parser.parse_args()
    print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; hilcontact {hc.__version__}")
    report: dict[str, object] = {
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.processor() or platform.platform()}",
        "python": sys.version.split()[0],
    }
    report["one_run"] = one_run()
    for name, stats in report["one_run"].items():  # type: ignore[union-attr]
        print(f"one paper-table1 pida run, {name}: median {stats['median_ms']:.2f} ms, p90 {stats['p90_ms']:.2f} ms; "
              f"CPU median {stats['cpu_median_ms']:.2f} ms")
    report["scaling"] = scaling()
    for row in report["scaling"]:  # type: ignore[union-attr]
        print(f"scaling {row}")
    if not args.skip_sweep:
        report["sweep"] = sweep(args.runs)
        s = report["sweep"]
        print(
            f"sweep of {s['runs']} runs: {s['wall_s']:.1f} s ({s['runs_per_s']:.0f} runs/s), "  # type: ignore[index]
            f"resident memory {s['rss_at_10pct_mib']:.0f} / {s['rss_at_50pct_mib']:.0f} / {s['rss_at_90pct_mib']:.0f} MiB "  # type: ignore[index]
            f"at 10 / 50 / 90 % of the runs, {s['rss_after_merge_mib']:.0f} MiB after merging the rows"  # type: ignore[index]
        )
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(report, handle, indent=1)


if __name__ == "__main__":
    main()
