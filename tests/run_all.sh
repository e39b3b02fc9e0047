#!/usr/bin/env bash
# The whole test suite: Rust unit and integration tests, then the Python side (tests, the Rust-vs-nlopt
# cross-check, the notebooks) in a venv it creates. Needs only cargo, Python 3.11 and pip.
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== cargo test"
cargo test --release --locked 2>&1

echo "== batch regression against fits/baselines (synthetic set; real scans when ../shared is present)"
NDFIT=target/release/ndfit bash fits/baselines/check.sh

# ---- Python side (owner: fits/). A venv of its own, numpy + nlopt from wheels, then the tests, the cross-check
# of the Rust fits against nlopt, and the notebooks. Needs only Python >= 3.9 (CI: 3.11) and pip.
if [ -f fits/pyproject.toml ]; then
  PY="${PYTHON:-python3}"
  echo "== python: venv and install"
  if [ ! -x fits/.venv/bin/python ]; then
    "$PY" -m venv fits/.venv
  fi
  fits/.venv/bin/python -m pip install --quiet --upgrade pip
  fits/.venv/bin/python -m pip install --quiet -e "fits[test,notebooks,render]"
  echo "== python tests"
  fits/.venv/bin/python -m pytest -q fits/tests
  if [ -z "${NDFIT:-}" ]; then
    cargo build --release --locked --bin ndfit 2>&1  # a no-op after cargo test --release, unless stale
  fi
  NDFIT_BIN="${NDFIT:-target/release/ndfit}"
  echo "== cross-check: Rust fits vs numpy + nlopt"
  fits/.venv/bin/python fits/crosscheck.py --ndfit "$NDFIT_BIN"
  echo "== notebooks"
  NDFIT="$NDFIT_BIN" fits/.venv/bin/python fits/run_notebooks.py notebooks
fi
