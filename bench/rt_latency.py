"""Wake-up latency of the real-time loop with and without real-time scheduling, on a loaded
machine (docs/realtime.md, "Real-time scheduling", quotes it).

    python bench/rt_latency.py [--duration 30] [--repeats 2] [--busy 2] [--configs normal,fifo,fifo-cpu1]
                               [--json FILE]

Each run is ``hilcontact demo-rt paper-table1`` (emulated facility and HIL loop in one
process on loopback: 1 kHz control and RDT, 250 Hz EGM, 20 ms robot delay, ``pida``) for
``--duration`` s, while ``--busy`` Python processes spin (``while True: pass``) to keep the
cores busy. Configurations:

- ``normal``: ``--rt-priority 0 --no-lock-memory`` (normal scheduling, what earlier versions did);
- ``fifo``: the defaults (SCHED_FIFO 80, memory locked);
- ``fifo-cpuN``: the defaults and ``--cpu N``.

Prints, per run, the wake-up latency p50/p99/max (µs), the period jitter p99 (µs), the overruns
what the OS granted (``realtime.scheduling``), the hypervisor's steal time and the load
average, then a Markdown table of the medians over the
repeats (the max: the largest). Runs alternate between the configurations, so that a change of
the machine's background load hits them alike.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

CONFIGS = {
    "normal": ["--rt-priority", "0", "--no-lock-memory"],
    "fifo": [],
}


def config_args(name: str) -> list[str]:
    if name in CONFIGS:
        return CONFIGS[name]
    if name.startswith("fifo-cpu") and name[len("fifo-cpu"):].isdigit():
        return ["--cpu", name[len("fifo-cpu"):]]
    raise SystemExit(f"unknown configuration {name!r}: normal, fifo or fifo-cpuN")


def start_load(n: int) -> list[subprocess.Popen[bytes]]:
    """`n` processes that each keep one core busy (pure user time, normal priority)."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def stop_load(load: list[subprocess.Popen[bytes]]) -> None:
    for p in load:
        p.terminate()
    for p in load:
        p.wait(timeout=10)


def cpu_times() -> list[int]:
    """The machine's CPU time counters (``/proc/stat`` ``cpu`` line, ticks; empty elsewhere)."""
    try:
        return [int(v) for v in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]
    except (OSError, ValueError, IndexError):
        return []


def steal_percent(before: list[int], after: list[int]) -> float | None:
    """Share of the CPU time the hypervisor gave to others (steal, field 8) between two
    readings, %."""
    if len(before) < 8 or len(after) < 8:
        return None
    delta = [b - a for a, b in zip(before, after)]
    return 100.0 * delta[7] / max(sum(delta), 1)


def run_interleaved(names: Sequence[str], repeats: int, run: Callable[[str, int], dict],
                    line: Callable[[dict], str]) -> list[dict]:
    """Runs ``run(name, i)`` ``repeats`` times per configuration, alternating between them (a
    change of the machine's background load hits them alike), printing ``line(result)`` after
    each run; returns the results, each with its ``config`` and ``repeat``. The one loop of the
    ``bench/rt_*.py`` scripts."""
    runs: list[dict] = []
    for i in range(repeats):
        for name in names:
            r = {"config": name, "repeat": i, **run(name, i)}
            runs.append(r)
            print(f"{name:10s} run {i + 1}: {line(r)}", flush=True)
    return runs


def median_table(runs: Sequence[dict], names: Sequence[str], first: str,
                 columns: Sequence[tuple[str, Callable[[list[dict]], Any]]]) -> None:
    """Prints a Markdown table, a row per configuration: ``first`` titles its name's column,
    each of ``columns`` is (title, its cell from the configuration's runs)."""
    print(f"\n| {first} | " + " | ".join(title for title, _ in columns) + " |")
    print("|---" * (len(columns) + 1) + "|")
    for name in names:
        rs = [r for r in runs if r["config"] == name]
        print(f"| {name} | " + " | ".join(str(cell(rs)) for _, cell in columns) + " |")


def median(rs: Sequence[dict], key: str) -> float:
    """The median of ``key`` over runs (those without it left out; NaN if none has it)."""
    values = [r[key] for r in rs if r.get(key) is not None]
    return statistics.median(values) if values else float("nan")


def run_once(name: str, duration: float, folder: Path) -> dict:
    out = folder / name
    before = cpu_times()
    cmd = [
        sys.executable, "-m", "hilcontact", "demo-rt", "paper-table1", "--set", f"simulation.duration={duration}",
        "--no-plots", "--out", str(out), *config_args(name),
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=duration + 120)
    if result.returncode not in (0, 3):
        raise SystemExit(f"{' '.join(cmd)}: exit {result.returncode}\n{result.stderr}{result.stdout}")
    steal = steal_percent(before, cpu_times())
    rt = json.loads((out / "metrics.json").read_text())["realtime"]
    lat, per = rt["timing"]["wake_latency_us"], rt["timing"]["period_error_us"]
    return {
        "ticks": rt["ticks"],
        "stop": rt["stop"]["kind"],
        "p50": lat["p50"], "p99": lat["p99"], "max": lat["max"],
        "period_p99": per["p99"],
        "overruns": rt["timing"]["overruns"],
        "scheduling": rt["scheduling"],
        "steal_percent": steal,
        "load_average": os.getloadavg()[0],
        "command": " ".join(cmd[1:]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=30.0, help="seconds per run [30]")
    parser.add_argument("--repeats", type=int, default=2, help="runs per configuration [2]")
    parser.add_argument("--busy", type=int, default=os.cpu_count() or 2, help="busy processes [one per CPU]")
    parser.add_argument("--configs", default="normal,fifo", help="comma-separated: normal, fifo, fifo-cpuN")
    parser.add_argument("--json", type=Path, default=None, help="write every run's numbers here")
    args = parser.parse_args()
    names = args.configs.split(",")
    for name in names:
        config_args(name)

    print(f"machine: {platform.platform()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at start; "
          f"{args.busy} busy processes; {args.duration:g} s per run", flush=True)
    def line(r: dict) -> str:
        s = r["scheduling"]
        return (f"wake latency p50/p99/max {r['p50']:.0f}/{r['p99']:.0f}/{r['max']:.0f} µs, "
                f"period jitter p99 {r['period_p99']:.0f} µs, overruns {r['overruns']} of {r['ticks']} "
                f"({r['stop']}); steal {r['steal_percent'] or 0:.1f} %, load average {r['load_average']:.1f}; "
                f"policy {s['policy']} {s['priority']}, memory locked {s['memory_locked']}, "
                f"pinned {s['pinned']}, refused {s['refused']}")

    load = start_load(args.busy)
    try:
        time.sleep(1.0)
        with tempfile.TemporaryDirectory(prefix="rt-latency-") as tmp:
            runs = run_interleaved(names, args.repeats,
                                   lambda name, i: run_once(name, args.duration, Path(tmp) / str(i)), line)
    finally:
        stop_load(load)

    median_table(runs, names, "scheduling", [
        ("wake-up latency p50", lambda rs: f"{median(rs, 'p50'):.0f} µs"),
        ("p99", lambda rs: f"{median(rs, 'p99'):.0f} µs"),
        ("max", lambda rs: f"{max(r['max'] for r in rs):.0f} µs"),
        ("period jitter p99", lambda rs: f"{median(rs, 'period_p99'):.0f} µs"),
        ("overruns (per run)", lambda rs: ", ".join(str(r["overruns"]) for r in rs)),
    ])
    if args.json is not None:
        args.json.write_text(json.dumps(runs, indent=1) + "\n")


if __name__ == "__main__":
    main()
