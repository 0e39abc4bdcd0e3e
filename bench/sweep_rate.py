"""Sweep throughput on this machine, runs per second (docs/performance.md quotes it).

    python bench/sweep_rate.py [--delays 50] [--seeds 5] [--compensators pida] [--repeat 5]
                               [--threads N] [--out] [--json FILE]

A sweep of ``paper-table1`` (0.2 N sensor noise) over ``--delays`` robot delays from 1 to
50 ms x ``--seeds`` seeds x the compensators (default ``pida``: 50 x 5 = 250 runs), on all
cores, as ``hc.sweep`` (``hilcontact sweep``) runs it, ``--repeat`` times. For each
repetition it prints the whole sweep's runs per second and its parts:

- ``plan``: validating every grid point and compensator (``plan_sweep``, Python);
- ``run``: running them (``run_plan``: the chunks through ``_core.simulate_batch``, the rows
  built, written to a folder with ``--out``);
- ``core``: the same runs' scenario JSONs through ``_core.simulate_batch`` alone (what the
  Rust threads cost, without the Python around them);
- the CPU time per run of the process (all threads): on a machine shared with other jobs the
  wall time measures them too, the CPU time much less; the number of cores divided by it is
  the rate an idle machine reaches if the threads scale.

The medians of the repetitions come last. The machine may be shared: compare medians of runs
made back to back, never single runs.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time

import hilcontact as hc
from hilcontact import _core
from hilcontact.sweep import plan_sweep, run_plan


def one(args: argparse.Namespace) -> dict[str, float]:
    grid = {"facility.robot_delay": f"0.001:0.05:{args.delays}"}
    overrides = {"facility.sensor_noise": 0.2}
    start, cpu_start = time.perf_counter(), time.process_time()
    plan = plan_sweep("paper-table1", grid, args.compensators, seeds=args.seeds, overrides=overrides, threads=args.threads)
    planned = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        out = os.path.join(folder, "s") if args.out else None
        rows = run_plan(plan, out, threads=args.threads)
    done, cpu_done = time.perf_counter(), time.process_time()
    assert len(rows) == plan.size, (len(rows), plan.size)
    jsons = [plan.scenario_json(p, k, s) for _, p, k, s in plan.runs()]
    core_start, core_cpu_start = time.perf_counter(), time.process_time()
    _core.simulate_batch(jsons, args.threads)
    core = time.perf_counter() - core_start
    core_cpu = time.process_time() - core_cpu_start
    n = plan.size
    return {
        "runs": n,
        "runs_per_s": n / (done - start),
        "plan_s": planned - start,
        "run_s": done - planned,
        "run_runs_per_s": n / (done - planned),
        "core_runs_per_s": n / core,
        # CPU time of the process (every thread) per run: on a busy machine, wall time measures
        # the other jobs too; cores / this is the rate of an idle machine that scales perfectly
        "cpu_ms_per_run": (cpu_done - cpu_start) / n * 1e3,
        "core_cpu_ms_per_run": core_cpu / n * 1e3,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--delays", type=int, default=50)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--compensators", default="pida")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--threads", type=int, default=None, help="Rust threads (default: one per core)")
    parser.add_argument("--out", action="store_true", help="write the results to a folder, as `hilcontact sweep --out` does")
    parser.add_argument("--json", default=None, help="also write the figures to this JSON file")
    args = parser.parse_args()
    print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; hilcontact {hc.__version__}")
    cores = args.threads or os.cpu_count() or 1
    reports = []
    for i in range(args.repeat):
        r = one(args)
        reports.append(r)
        print(
            f"#{i + 1}: {r['runs']} runs, {r['runs_per_s']:.0f} runs/s in all "
            f"(plan {r['plan_s'] * 1e3:.0f} ms, run {r['run_s'] * 1e3:.0f} ms = {r['run_runs_per_s']:.0f} runs/s); "
            f"core alone {r['core_runs_per_s']:.0f} runs/s; CPU {r['cpu_ms_per_run']:.2f} ms per run "
            f"(core alone {r['core_cpu_ms_per_run']:.2f})"
        )
    median = {k: statistics.median(r[k] for r in reports) for k in reports[0]}
    print(
        f"median of {args.repeat}: {median['runs_per_s']:.0f} runs/s in all, {median['run_runs_per_s']:.0f} runs/s "
        f"without the plan, core alone {median['core_runs_per_s']:.0f} runs/s; CPU {median['cpu_ms_per_run']:.2f} ms "
        f"per run (core alone {median['core_cpu_ms_per_run']:.2f}): {cores / median['cpu_ms_per_run'] * 1e3:.0f} runs/s "
        f"on {cores} idle cores if they scale"
    )
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump({"repetitions": reports, "median": median}, handle, indent=1)


if __name__ == "__main__":
    main()
