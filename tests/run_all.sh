#!/usr/bin/env bash
# The whole test suite: Rust unit and integration tests, then the Python side (tests, the Rust-vs-nlopt
# cross-check, the notebooks) in a venv it creates. Needs only cargo, Python >= 3.9 (CI: 3.11) and pip.
set -euo pipefail
cd "$(dirname "$0")/.."
# Each stage's header names the minutes and seconds since the start, so a slow stage shows in the log.
stage() { printf '== %s  [%dm%02ds]\n' "$*" $((SECONDS / 60)) $((SECONDS % 60)); }
trap 'stage "end (exit $?)"' EXIT

# The Python venv is made and filled in the background while cargo compiles (pip waits on the network and
# the disk, cargo on the cores); its log is shown when the Python side starts below.
PY_SETUP_PID=""
PY_SETUP_LOG="$(mktemp)"
if [ -f fits/pyproject.toml ]; then
  PY="${PYTHON:-python3}"
  (
    set -e
    if [ ! -x fits/.venv/bin/python ]; then
      "$PY" -m venv fits/.venv
    fi
    fits/.venv/bin/python -m pip install --quiet --upgrade pip
    fits/.venv/bin/python -m pip install --quiet -e "fits[test,notebooks,render]"
  ) >"$PY_SETUP_LOG" 2>&1 &
  PY_SETUP_PID=$!
fi

stage "cargo test"
cargo test --release --locked 2>&1
if [ ! -f ../shared/data/scans/peer_readings.json ]; then
  if [ -n "${NDFIT_REQUIRE_SHARED:-}" ] && [ "${NDFIT_REQUIRE_SHARED}" != 0 ]; then
    echo "FAIL: ../shared/data/scans is absent and NDFIT_REQUIRE_SHARED is set (the *_needs_shared tests failed above)" >&2
    exit 1
  fi
  echo "NOTE: ../shared/data/scans is absent: every test named *_needs_shared above passed by SKIPPING its real-scan"
  echo "      checks, and the real-scan parts below are skipped too (NDFIT_REQUIRE_SHARED=1 makes this a failure)"
fi

stage "lints: clippy and rustdoc (warnings are errors); the library alone builds without clap, indicatif, plotters"
cargo clippy --release --locked --workspace --all-targets -- -D warnings 2>&1
# `--release`: the dependencies' metadata checked by clippy above serves rustdoc too where their features agree.
RUSTDOCFLAGS=-Dwarnings cargo doc --release --locked --no-deps 2>&1
if cargo tree --locked -e normal --no-default-features | grep -E '^[^a-z]*(clap|indicatif|plotters) '; then
  echo "FAIL: the library without default features depends on clap, indicatif or plotters" >&2
  exit 1
fi

stage "batch regression against fits/baselines (synthetic set; real scans when ../shared is present)"
NDFIT=target/release/ndfit bash fits/baselines/check.sh

# ---- Python side (owner: fits/). A venv of its own, numpy + nlopt from wheels, then the tests, the cross-check
# of the Rust fits against nlopt, and the notebooks. Needs only Python >= 3.9 (CI: 3.11) and pip.
if [ -f fits/pyproject.toml ]; then
  stage "python: venv and install (started in the background at the beginning)"
  if ! wait "$PY_SETUP_PID"; then
    cat "$PY_SETUP_LOG"
    echo "FAIL: the Python venv could not be set up (fits/.venv, pip install -e fits[test,notebooks,render])" >&2
    exit 1
  fi
  cat "$PY_SETUP_LOG"
  # `cargo test --release` above built target/release/ndfit (the integration tests run it); a separate
  # `cargo build --bin ndfit` would resolve the dependencies' features without the dev-dependencies and
  # rebuild them all, minutes on CI.
  if [ -z "${NDFIT:-}" ] && [ ! -x target/release/ndfit ]; then
    cargo build --release --locked --bin ndfit 2>&1
  fi
  NDFIT_BIN="${NDFIT:-target/release/ndfit}"
  # The Python package (`import ndfit`, python/): pip builds the extension with maturin into the same
  # target/ as cargo above. Its dependencies resolve to other features than the test build's (no
  # dev-dependencies, ndfit without `cli`), so most of them compile again: minutes, run beside the Python
  # tests (which never import the package and leave a core free most of the time).
  PKG_LOG="$(mktemp)"
  fits/.venv/bin/python -m pip install --quiet "./[test]" >"$PKG_LOG" 2>&1 &
  PKG_PID=$!
  stage "python tests (the ndfit package builds beside them)"
  fits/.venv/bin/python -m pytest -q fits/tests
  stage "python: the ndfit package (pip install ./, maturin): waiting for its build"
  if ! wait "$PKG_PID"; then
    cat "$PKG_LOG"
    echo "FAIL: the ndfit Python package did not build (pip install ./[test])" >&2
    exit 1
  fi
  cat "$PKG_LOG"
  stage "python package tests"
  NDFIT="$NDFIT_BIN" fits/.venv/bin/python -m pytest -q python/tests
  stage "cross-check: Rust fits vs numpy + nlopt (one scan per core)"
  fits/.venv/bin/python fits/crosscheck.py --ndfit "$NDFIT_BIN"
  stage "notebooks (one per core)"
  NDFIT="$NDFIT_BIN" fits/.venv/bin/python fits/run_notebooks.py notebooks
fi

# Last, so a tree the lead has not formatted yet still runs every test above.
stage "rustfmt"
cargo fmt --check
