#!/usr/bin/env bash
# Measures the real-time loop on this machine: the emulated facility and the HIL loop as two
# processes on loopback (paper-table1, 20 ms robot delay, pida, 1 kHz sensor, 250 Hz robot),
# then prints the timing and packet statistics of metrics.json. Used for docs/realtime.md.
# Usage: scripts/measure-realtime.sh [DURATION_S] [OUT_DIR]   (default 30 s, runs/measure-rt)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
PYTHON="${PYTHON:-$(command -v python || command -v python3)}"
DURATION="${1:-30}"
OUT="${2:-runs/measure-rt}"
free_port() { "$PYTHON" -c "import socket,sys; s=socket.socket(socket.AF_INET, getattr(socket, sys.argv[1])); s.bind(('127.0.0.1',0)); print(s.getsockname()[1])" "$1"; }
SENSOR=$(free_port SOCK_DGRAM); EGM=$(free_port SOCK_DGRAM); HTTP=$(free_port SOCK_STREAM)
LOG=$(mktemp)
"$PYTHON" -m hilcontact facility paper-table1 --set facility.robot_delay=0.02 \
    --sensor-port "$SENSOR" --http-port "$HTTP" --egm-port "$EGM" >"$LOG" 2>/dev/null &
FACILITY=$!
trap 'kill -TERM $FACILITY 2>/dev/null || true; wait $FACILITY 2>/dev/null || true; cat "$LOG"; rm -f "$LOG"' EXIT
for _ in $(seq 100); do grep -q '^ready' "$LOG" && break; sleep 0.1; done
"$PYTHON" -m hilcontact hil paper-table1 --set facility.robot_delay=0.02 --set compensator.kind=pida \
    --set simulation.duration="$DURATION" --sensor 127.0.0.1 --sensor-port "$SENSOR" --http-port "$HTTP" \
    --egm-port "$EGM" --egm-bind 127.0.0.1 --out "$OUT" --no-plots || true
"$PYTHON" - "$OUT/metrics.json" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
rt = m["realtime"]
print(json.dumps({k: rt[k] for k in ("ticks", "wall_time", "timing", "sensor", "robot", "samples_dropped", "stop")}, indent=1))
print("CoV:", [round(c["cov"], 4) for c in m["collisions"] if c["cov"] is not None])
print("CoF:", [round(c["cof"], 4) for c in m["collisions"] if c["cof"] is not None])
PY
