"""The live view's cost to the real-time loop (docs/realtime.md, "Live view", quotes it): the
loop's wake-up latency, overruns and the process's peak memory without ``--live``, with one
viewer that keeps up, with a viewer that stops reading, and with 20 viewers.

    python bench/rt_live.py [--duration 10] [--repeats 3] [--configs none,one,stalled,clients20] [--json FILE]
    python bench/rt_live.py --from-json FILE      # the table again, from a run's --json

Each run is ``hilcontact demo-rt paper-table1`` (emulated facility and HIL loop in one process
on loopback: 1 kHz, 20 ms robot delay, ``pida``) for ``--duration`` s. Configurations:

- ``none``: no ``--live``;
- ``one``: ``--live``, one viewer subscribed to every channel, reading everything;
- ``stalled``: ``--live``, one viewer that subscribes to every channel and then never reads
  (its socket buffers fill, then the server's per-client queue, bounded by the live view's
  ``backlog``, 4096 messages, drops the oldest);
- ``clients20``: ``--live``, 20 viewers subscribed to every channel, each reading everything.

With ``--live`` the run starts once a viewer has subscribed (``--live-wait``). Runs alternate
between the configurations (bench/rt_latency.py's ``run_interleaved``), so that a change of the
machine's background load hits them alike; the table gives the medians over the repeats, and
each configuration's p99 and overruns against ``none``'s. Peak memory is the process's
``VmHWM`` (Linux). The live counters are ``metrics.json`` ``realtime.live``'s: messages
published, the SDK's "outbox full" reports (a client lost its oldest messages) and the loop's
own ``samples_dropped`` (its ring to the writer thread, which feeds the live view).
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import platform
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from rt_latency import cpu_times, median, median_table, run_interleaved, steal_percent  # noqa: E402

#: Viewers per configuration, and whether they read.
CONFIGS = {"none": (0, True), "one": (1, True), "stalled": (1, False), "clients20": (20, True)}


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def connect(port: int, timeout: float = 60.0) -> socket.socket:
    """A viewer subscribed to every channel (foxglove.sdk.v1), its socket positioned after the
    subscription."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            sock = socket.create_connection(("127.0.0.1", port), timeout=5)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)
    sock.settimeout(30)
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                  f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                  f"Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n").encode())
    buf = b""
    while b"\r\n\r\n" not in buf:
        buf += sock.recv(4096)
    buf = buf.split(b"\r\n\r\n", 1)[1]

    def exact(n: int) -> bytes:
        nonlocal buf
        while len(buf) < n:
            buf += sock.recv(1 << 16)
        out, buf = buf[:n], buf[n:]
        return out

    while True:
        b0, b1 = exact(2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack(">H", exact(2))[0]
        elif n == 127:
            n = struct.unpack(">Q", exact(8))[0]
        data = exact(n)
        if b0 & 0x0F == 1 and json.loads(data).get("op") == "advertise":
            ids = [c["id"] for c in json.loads(data)["channels"]]
            break
    message = json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": c} for i, c in enumerate(ids)]})
    mask = os.urandom(4)
    payload = message.encode()
    head = bytes([0x81, 0x80 | 126]) + struct.pack(">H", len(payload)) if len(payload) >= 126 else bytes([0x81, 0x80 | len(payload)])
    sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))
    return sock


def drain(sock: socket.socket) -> None:
    try:
        while sock.recv(1 << 16):
            pass
    except OSError:
        pass


def peak_memory_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def run_once(name: str, duration: float, folder: Path) -> dict:
    viewers, reading = CONFIGS[name]
    out = folder / name
    port = free_tcp_port()
    cmd = [sys.executable, "-m", "hilcontact", "demo-rt", "paper-table1", "--set", f"simulation.duration={duration}",
           "--no-plots", "--out", str(out)]
    if viewers:
        cmd += ["--live", str(port), "--live-wait", "60"]
    before = cpu_times()
    process = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sockets: list[socket.socket] = []
    for _ in range(viewers):
        s = connect(port)
        sockets.append(s)
        if reading:
            threading.Thread(target=drain, args=(s,), daemon=True).start()
    peak = None
    while process.poll() is None:
        peak = peak_memory_mb(process.pid) or peak
        time.sleep(0.2)
    stdout, stderr = process.communicate()
    for s in sockets:
        s.close()
    if process.returncode not in (0, 3):
        raise SystemExit(f"{' '.join(cmd)}: exit {process.returncode}\n{stderr}{stdout}")
    rt = json.loads((out / "metrics.json").read_text())["realtime"]
    lat = rt["timing"]["wake_latency_us"]
    live = rt.get("live") or {}
    return {
        "ticks": rt["ticks"], "stop": rt["stop"]["kind"],
        "p50": lat["p50"], "p99": lat["p99"], "max": lat["max"], "overruns": rt["timing"]["overruns"],
        "samples_dropped": rt["samples_dropped"], "peak_mb": peak,
        "live_messages": live.get("messages"), "peak_clients": live.get("peak_clients"),
        "outbox_full_reports": live.get("outbox_full_reports"), "lossy_clients": live.get("lossy_clients"),
        "scheduling": rt["scheduling"], "steal_percent": steal_percent(before, cpu_times()),
        "load_average": os.getloadavg()[0], "command": " ".join(cmd[1:]),
    }


def line(r: dict) -> str:
    s = r["scheduling"]
    return (f"wake latency p50/p99/max {r['p50']:.0f}/{r['p99']:.0f}/{r['max']:.0f} µs, "
            f"overruns {r['overruns']} of {r['ticks']} ({r['stop']}), samples dropped {r['samples_dropped']}, "
            f"peak memory {r['peak_mb'] or 0:.1f} MB, live messages {r['live_messages']}, "
            f"peak clients {r['peak_clients']}, outbox full {r['outbox_full_reports']} {r['lossy_clients'] or ''}; "
            f"load average {r['load_average']:.1f}, steal {r['steal_percent'] or 0:.1f} %; "
            f"policy {s['policy']} {s['priority']}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=10.0, help="seconds per run [10]")
    parser.add_argument("--repeats", type=int, default=3, help="runs per configuration [3]")
    parser.add_argument("--configs", default="none,one,stalled,clients20", help=f"comma-separated: {', '.join(CONFIGS)}")
    parser.add_argument("--json", type=Path, default=None, help="write every run's numbers here")
    parser.add_argument("--from-json", type=Path, default=None, help="print the table of the runs of this --json file")
    args = parser.parse_args()
    names = args.configs.split(",")
    for name in names:
        if name not in CONFIGS:
            raise SystemExit(f"unknown configuration {name!r}: {', '.join(CONFIGS)}")
    if args.from_json is not None:
        runs = json.loads(args.from_json.read_text())
        names = [n for n in names if any(r["config"] == n for r in runs)]
        loads = [r["load_average"] for r in runs]
        print(f"{len(runs)} runs from {args.from_json}; load average {min(loads):.1f} to {max(loads):.1f}")
        table(runs, names)
        return
    print(f"machine: {platform.platform()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at start; "
          f"{args.duration:g} s per run", flush=True)
    with tempfile.TemporaryDirectory(prefix="rt-live-") as tmp:
        runs = run_interleaved(names, args.repeats,
                               lambda name, i: run_once(name, args.duration, Path(tmp) / str(i)), line)
    print(f"load average at the end {os.getloadavg()[0]:.2f}")
    table(runs, names)
    if args.json is not None:
        args.json.write_text(json.dumps(runs, indent=1) + "\n")


def table(runs: list[dict], names: list[str]) -> None:
    """The medians per configuration, against ``none``'s."""
    base = [r for r in runs if r["config"] == "none"]

    def versus(key: str):
        def cell(rs: list[dict]) -> str:
            if not base or rs[0]["config"] == "none":
                return "-"
            return f"{100 * (median(rs, key) / max(median(base, key), 1e-9) - 1):+.0f} %"
        return cell

    def stops(rs: list[dict]) -> str:
        kinds = sorted({r["stop"] for r in rs})
        return ", ".join(f"{sum(r['stop'] == k for r in rs)} {k}" for k in kinds)

    median_table(runs, names, "live view", [
        ("wake-up latency p50", lambda rs: f"{median(rs, 'p50'):.0f} µs"),
        ("p99", lambda rs: f"{median(rs, 'p99'):.0f} µs"),
        ("p99 vs none", versus("p99")),
        ("max", lambda rs: f"{max(r['max'] for r in rs):.0f} µs"),
        ("overruns (per run)", lambda rs: ", ".join(str(r["overruns"]) for r in rs)),
        ("overruns, median", lambda rs: f"{median(rs, 'overruns'):.0f}"),
        ("vs none", versus("overruns")),
        ("runs ended", stops),
        ("peak memory", lambda rs: f"{median(rs, 'peak_mb'):.1f} MB"),
        ("samples dropped", lambda rs: sum(r["samples_dropped"] for r in rs)),
        ("outbox full reports", lambda rs: ", ".join(str(r["outbox_full_reports"]) for r in rs)),
    ])


if __name__ == "__main__":
    main()
