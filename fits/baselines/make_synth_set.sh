#!/usr/bin/env bash
# The synthetic regression set of `ndfit batch`: small scans (256 x 256) made by `ndfit synth` with fixed
# seeds, so the set is identical on every machine. Usage: make_synth_set.sh NDFIT_BINARY OUT_DIR
set -euo pipefail
NDFIT="$1"
OUT="$2"
rm -rf "$OUT"
mkdir -p "$OUT/ellipsoid" "$OUT/gaussian" "$OUT/degraded"
grid=(--nx 256 --ny 256 --dx 1e-6)
s() { "$NDFIT" synth "$@" >/dev/null; }
# Ellipsoid caps: the NDF is exactly the ellipsoid NDF (Walter et al. eq. 1).
s "$OUT/ellipsoid/iso_smooth.x3p"  --surface ellipsoid "${grid[@]}" --seed 1 --alpha-x 0.05
s "$OUT/ellipsoid/iso_medium.x3p"  --surface ellipsoid "${grid[@]}" --seed 1 --alpha-x 0.3
s "$OUT/ellipsoid/iso_rough.x3p"   --surface ellipsoid "${grid[@]}" --seed 1 --alpha-x 1.2
s "$OUT/ellipsoid/aniso.x3p"       --surface ellipsoid "${grid[@]}" --seed 1 --alpha-x 0.4 --alpha-y 0.1 --theta-z 0.6
s "$OUT/ellipsoid/skew_x.x3p"      --surface ellipsoid "${grid[@]}" --seed 1 --alpha-x 0.25 --theta-x 0.45
s "$OUT/ellipsoid/skew_yz.x3p"     --surface ellipsoid "${grid[@]}" --seed 1 --alpha-x 0.35 --alpha-y 0.2 --theta-y -0.35 --theta-z 1.0
# Gaussian random surfaces: anisotropic Beckmann with alpha = sqrt(2) sigma (Heitz footnote 3).
s "$OUT/gaussian/iso.x3p"          --surface gaussian "${grid[@]}" --seed 11 --sigma-x 0.2
s "$OUT/gaussian/aniso.x3p"        --surface gaussian "${grid[@]}" --seed 12 --sigma-x 0.3 --sigma-y 0.1 --theta-z -0.4
# Degraded: holes and noise, a huge height offset.
s "$OUT/degraded/holes_noise.x3p"  --surface ellipsoid "${grid[@]}" --seed 21 --alpha-x 0.3 --alpha-y 0.2 --holes 0.05 --noise 2e-9
s "$OUT/degraded/offset.x3p"       --surface ellipsoid "${grid[@]}" --seed 22 --alpha-x 0.2 --offset 0.5
