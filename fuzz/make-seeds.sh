#!/usr/bin/env bash
# Regenerates the blob seeds of fuzz/corpus/blob_eval with the current blob format (run after a
# format version change; the CSV/model-file seeds of csv_import are hand-written and kept).
#
#   bash fuzz/make-seeds.sh
#
# Seeds: RR 6 × 6 grid Heun × 5; RR 4 × 4 RK4 × 2; RR 4 × 4 Euler × 3 without the divergence term;
# UR5 40 rows (Euler × 1); UR5 40 rows on a model file carrying every effect type.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="$ROOT/fuzz/corpus/blob_eval"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
cd "$ROOT"
cargo build -q --release -p cbd-trainer --bin cbd
cbd="$ROOT/target/release/cbd"

"$cbd" simulate --sampling grid --grid 6 --out "$tmp/g6.csv" >/dev/null
"$cbd" simulate --sampling grid --grid 4 --out "$tmp/g4.csv" >/dev/null
head -n 41 examples/ur5/train.csv >"$tmp/ur5.csv"
# Every effect type, in the model file's units (degrees, mm).
cat examples/ur5/ur5.toml - >"$tmp/ur5-effects.toml" <<'EOF'

[gravity]
direction = [0, 0, -1]
link_masses = [3.7, 8.4, 2.3, 1.2, 1.2, 0.2]

[[effects]]
type = "gravity_compliance"
joint = 2
compliance = 1e-6

[[effects]]
type = "transmission"
joint = 3
harmonic = 2
cos = 0.01
sin = -0.02

[[effects]]
type = "encoder_scale"
joint = 1
scale = 2e-4

[[effects]]
type = "link_bending"
link = 3
compliance = 0.05
EOF

rm -f "$OUT"/*.blob
"$cbd" fit --quiet --data "$tmp/g6.csv" --integrator heun --steps 5 --out "$OUT/rr_grid6_heun5.blob"
"$cbd" fit --quiet --data "$tmp/g4.csv" --integrator rk4 --steps 2 --out "$OUT/rr_grid4_rk4.blob"
"$cbd" fit --quiet --data "$tmp/g4.csv" --integrator euler --steps 3 --no-divergence --out "$OUT/rr_grid4_euler_nodiv.blob"
"$cbd" fit --quiet --model examples/ur5/ur5.toml --data "$tmp/ur5.csv" --out "$OUT/ur5_40rows.blob"
"$cbd" fit --quiet --model "$tmp/ur5-effects.toml" --data "$tmp/ur5.csv" --out "$OUT/ur5_40rows_effects.blob"
ls -l "$OUT"
