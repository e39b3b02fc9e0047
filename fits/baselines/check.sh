#!/usr/bin/env bash
# CI: refit the synthetic regression set (and the real scans, when ../shared is present) and compare
# against the checked-in baselines. Exit status is ndfit batch's: 0 clean, 1 regressed, 2 unreadable;
# 2 also when the real scans are absent and NDFIT_REQUIRE_SHARED is set (.ci/run sets it).
# NDFIT=path/to/ndfit overrides the release build.
set -euo pipefail
cd "$(dirname "$0")/../.."
if [ -z "${NDFIT:-}" ]; then
  cargo build --release --locked --bin ndfit
  NDFIT=target/release/ndfit
fi
bash fits/baselines/make_synth_set.sh "$NDFIT" target/batch-synth
echo "-- synthetic set against fits/baselines/synth/summary.json"
"$NDFIT" batch target/batch-synth -o target/batch-synth-check --model auto --jobs 2 \
  --baseline fits/baselines/synth/summary.json
if [ -f ../shared/data/scans/peer_readings.json ] && [ -f fits/baselines/real/summary.json ]; then
  echo "-- real scans against fits/baselines/real/summary.json"
  "$NDFIT" batch ../shared/data/scans -o target/batch-real-check --model auto --jobs 2 \
    --baseline fits/baselines/real/summary.json
elif [ -n "${NDFIT_REQUIRE_SHARED:-}" ] && [ "${NDFIT_REQUIRE_SHARED}" != 0 ]; then
  echo "FAIL real scans: ../shared/data/scans/peer_readings.json or fits/baselines/real/summary.json is absent" \
    "and NDFIT_REQUIRE_SHARED is set" >&2
  exit 2
else
  echo "SKIP real scans: ../shared/data/scans or fits/baselines/real/summary.json is absent" \
    "(NDFIT_REQUIRE_SHARED=1 makes this a failure)"
fi
