#!/usr/bin/env bash
# The whole test suite: Rust unit and integration tests, then the Python side (tests, the Rust-vs-nlopt
# cross-check, the notebooks) in a venv it creates. Needs only cargo, Python 3.11 and pip.
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== cargo test"
cargo test --release --locked 2>&1

echo "== batch regression against fits/baselines (synthetic set; real scans when ../shared is present)"
NDFIT=target/release/ndfit bash fits/baselines/check.sh

if [ -f fits/pyproject.toml ]; then
  echo "== python: venv and install"
  if [ ! -x fits/.venv/bin/python ]; then
    python3 -m venv fits/.venv
  fi
  fits/.venv/bin/python -m pip install --quiet --upgrade pip
  fits/.venv/bin/python -m pip install --quiet -e "fits[test]"
  echo "== python tests"
  fits/.venv/bin/python -m pytest -q fits/tests
fi
