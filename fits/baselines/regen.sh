#!/usr/bin/env bash
# Regenerate the checked-in baselines of `ndfit batch`:
#   fits/baselines/synth/summary.json  the synthetic set of make_synth_set.sh, fitted with --model auto
#   fits/baselines/real/summary.json   the real scans of ../shared/data/scans (when present)
# Run from anywhere; NDFIT=path/to/ndfit overrides the release build. Review the diff before committing:
# a baseline is the statement "these fits are good".
set -euo pipefail
cd "$(dirname "$0")/../.."
if [ -z "${NDFIT:-}" ]; then
  cargo build --release --locked --bin ndfit
  NDFIT=target/release/ndfit
fi
bash fits/baselines/make_synth_set.sh "$NDFIT" target/batch-synth
"$NDFIT" batch target/batch-synth -o target/batch-synth-base --model auto
mkdir -p fits/baselines/synth
cp target/batch-synth-base/summary.json fits/baselines/synth/summary.json
if [ -f ../shared/data/scans/peer_readings.json ]; then
  "$NDFIT" batch ../shared/data/scans -o target/batch-real-base --model auto
  mkdir -p fits/baselines/real
  cp target/batch-real-base/summary.json fits/baselines/real/summary.json
fi
echo "baselines regenerated; review with: git diff --stat fits/baselines"
