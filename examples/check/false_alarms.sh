#!/bin/sh
# `cbd check` on the simulated six-joint arm (issue 50 items 1 and 2): calibrate once on 300 poses
# (noise 0.02 mm), then draw independent sets of fresh poses from the same arm and count how often
# the check says "changed" — with nothing changed (the false-alarm rate, which must lie within
# [0.5 α, 2 α]), with the tracker set up anew (rigid 1 m / 30°, --register), and with planted
# changes (the detection rate). Run from the repository root:
#
#   sh examples/check/false_alarms.sh            # SETS=200 fresh sets of POSES=20 poses each
#   SETS=50 POSES=20 sh examples/check/false_alarms.sh
#
# Prints one table row per scenario: sets, rejections at α = 0.05 and 0.01, and the rates.
set -eu
CBD=${CBD:-target/release/cbd}
MODEL=examples/ur5/simulated-six.toml
SETS=${SETS:-200}
POSES=${POSES:-20}
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT

$CBD simulate --robot six --sampling uniform --count 300 --noise 0.02 --seed 1 --out "$W/cal.csv" >/dev/null 2>&1
$CBD fit --model "$MODEL" --data "$W/cal.csv" --out "$W/arm.blob" >"$W/fit.log" 2>&1

# p of one fresh set: $1 seed, $2 extra simulate flags, $3 extra check flags, $4 a filter on the CSV.
p_of() {
    # shellcheck disable=SC2086
    $CBD simulate --robot six --sampling uniform --count "$POSES" --noise 0.02 --seed "$1" $2 --out "$W/raw.csv" >/dev/null 2>&1
    eval "$4" <"$W/raw.csv" >"$W/fresh.csv"
    # shellcheck disable=SC2086
    $CBD check --model "$MODEL" --blob "$W/arm.blob" --data "$W/fresh.csv" --alpha 0.05 --json "$W/check.json" $3 >/dev/null || [ $? -eq 3 ]
    sed -n 's/.*"p_value": \([^,]*\),*/\1/p' "$W/check.json"
}

# $1 name, $2 simulate flags, $3 check flags, $4 CSV filter.
scenario() {
    r05=0
    r01=0
    s=0
    while [ "$s" -lt "$SETS" ]; do
        p=$(p_of $((1000 + s)) "$2" "$3" "$4")
        r05=$(awk -v p="$p" -v r="$r05" 'BEGIN { print r + (p < 0.05) }')
        r01=$(awk -v p="$p" -v r="$r01" 'BEGIN { print r + (p < 0.01) }')
        s=$((s + 1))
    done
    awk -v n="$1" -v s="$SETS" -v a="$r05" -v b="$r01" 'BEGIN { printf "| %s | %d | %d (%.3f) | %d (%.3f) |\n", n, s, a, a / s, b, b / s }'
}

# A joint's zero moved by $2 degrees: the encoder of joint $1 reads q − δ for the same arm pose.
joint_zero() { echo "awk -F, -v OFS=, -v c=$1 -v d=$2 'NR > 1 { \$c = \$c - d } { print }'"; }
# A uniform length scale (temperature): every measured position × $1 about the base.
length_scale() { echo "awk -F, -v OFS=, -v s=$1 'NR > 1 { \$7 *= s; \$8 *= s; \$9 *= s } { print }'"; }

echo "| scenario ($POSES poses per set) | sets | changed at α = 0.05 | changed at α = 0.01 |"
echo "|---|---|---|---|"
scenario "no change" "" "" cat
scenario "no change, --register" "" "--register" cat
scenario "tracker moved 1 m / 30°, --register" "--tracker-frame 577.35,577.35,577.35;1,2,3,30" "--register" cat
scenario "joint 2 zero +0.002°" "" "" "$(joint_zero 2 0.002)"
scenario "joint 2 zero +0.002°, --register" "" "--register" "$(joint_zero 2 0.002)"
scenario "base shift 0.02 mm (x)" "--tracker-frame 0.02,0,0;0,0,1,0" "" cat
scenario "length scale 1 + 5e-5" "" "" "$(length_scale 1.00005)"
