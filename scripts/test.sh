#!/usr/bin/env bash
# The project's test command: Rust tests, then build and install the Python package (with
# the native extension) and run the Python tests. Needs Rust, Python >= 3.11, maturin, pytest.
# The interpreter: $PYTHON if set, else the active virtual environment's ($VIRTUAL_ENV/bin/python),
# else the repository's .venv (README's set-up), else python3 on the PATH.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

if [[ -z "${PYTHON:-}" ]]; then
    if [[ -n "${VIRTUAL_ENV:-}" && -x "$VIRTUAL_ENV/bin/python" ]]; then
        PYTHON="$VIRTUAL_ENV/bin/python"
    elif [[ -x .venv/bin/python ]]; then
        PYTHON="$PWD/.venv/bin/python"
    else
        PYTHON="$(command -v python3 || command -v python || true)"
    fi
fi
PYTHON="$(command -v "$PYTHON" || true)"
if [[ -z "$PYTHON" ]]; then
    echo "scripts/test.sh: no python interpreter found (set PYTHON, or activate a virtual environment)" >&2
    exit 1
fi
echo "==> python: $PYTHON ($("$PYTHON" --version 2>&1))"

echo "==> cargo test --release"
cargo test --release

echo "==> $PYTHON -m pip install '.[test]'"
"$PYTHON" -m pip install -q '.[test]'

echo "==> $PYTHON -m pytest -q tests"
"$PYTHON" -m pytest -q tests
