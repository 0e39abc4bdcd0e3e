#!/usr/bin/env bash
# The project's test command: Rust tests, then build and install the Python package (with
# the native extension) and run the Python tests. Needs Rust, Python >= 3.11, maturin, pytest.
# Set PYTHON to choose the interpreter (default: python, else python3).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

PYTHON="${PYTHON:-$(command -v python || command -v python3 || true)}"
if [[ -z "$PYTHON" ]]; then
    echo "scripts/test.sh: no python interpreter found (set PYTHON)" >&2
    exit 1
fi

echo "==> cargo test --release"
cargo test --release

echo "==> $PYTHON -m pip install '.[test]'"
"$PYTHON" -m pip install -q '.[test]'

echo "==> $PYTHON -m pytest -q tests"
"$PYTHON" -m pytest -q tests
