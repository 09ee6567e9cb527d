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
# Prints one table row per scenario: sets, rejections at α = 0.05 and 0.01 with their rates, and the
# mean of statistic / dof (1 when the law holds). Planted changes: `cbd simulate --effect` (the same arm).
set -eu
. examples/check/common.sh
SETS=${SETS:-200}
POSES=${POSES:-20}
calibrate --sampling uniform --noise 0.02

# p, statistic and dof of one fresh set: $1 seed, $2 extra simulate flags, $3 extra check flags.
p_of() {
    # shellcheck disable=SC2086
    $CBD simulate --robot six --sampling uniform --count "$POSES" --noise 0.02 --seed "$1" $2 --out "$W/fresh.csv" >/dev/null 2>&1
    # shellcheck disable=SC2086
    check_fresh $3
    p_statistic_dof
}

# One table row: $1 name, $2 simulate flags, $3 check flags. The fresh sets' seeds 1000, 1001, …
# are the same in every scenario (the calibration's is 1).
scenario() {
    s=0
    : >"$W/p.txt"
    while [ "$s" -lt "$SETS" ]; do
        p_of $((1000 + s)) "$2" "$3" >>"$W/p.txt"
        s=$((s + 1))
    done
    awk -v n="$1" '{ a += ($1 < 0.05); b += ($1 < 0.01); r += $2 / $3; k++ }
        END { printf "| %s | %d | %d (%.3f) | %d (%.3f) | %.3f |\n", n, k, a, a / k, b, b / k, r / k }' "$W/p.txt"
}

echo "| scenario ($POSES random poses per set) | sets | changed at α = 0.05 | changed at α = 0.01 | mean statistic / dof |"
echo "|---|---|---|---|---|"
scenario "no change" "" ""
scenario "no change, --register" "" "--register"
scenario "tracker moved 1 m / 30°, --register" "--tracker-frame 577.35,577.35,577.35;1,2,3,30" "--register"
scenario "joint 2 zero 1e-4 rad (0.0057°)" "--effect joint_zero:joint=2,offset=1e-4" ""
scenario "joint 2 zero 1e-4 rad, --register" "--effect joint_zero:joint=2,offset=1e-4" "--register"
scenario "joint 2 zero 3.5e-5 rad (0.002°)" "--effect joint_zero:joint=2,offset=3.5e-5" ""
scenario "base shift 0.05 mm (x)" "--effect base_shift:dx=0.05" ""
scenario "tool shift 0.05 mm (flange z)" "--effect tool_shift:dz=0.05" ""
scenario "link 3 length +0.05 mm" "--effect link_length:link=3,delta=0.05" ""
scenario "length scale 1 + 1e-4" "--effect length_scale:scale=1.0001" ""
