#!/bin/sh
# `cbd check` when the rows drift in measurement order (issue 50 item 1: "the part of the residual
# that is correlated in measurement order … leaving it out makes false alarms"): the simulated
# six-joint arm with a stationary drift over its rows (sd 0.03 mm, correlation length 8 poses) on
# top of noise 0.02 mm (`--effect drift`: the arm is then its geometry without the built-in joint
# compliance, the same for calibration and fresh rows), calibrated once on 300 poses; `cbd fit`
# records the drift in the blob. Then SETS independent sets of POSES fresh poses, each with its own
# drift, checked. Uniform random poses by default; DRIFT= sets the simulate flags (a random walk, as
# a real campaign, whose fresh walks lie away from the calibration's). Run from the repository root:
#
#   sh examples/check/drift_false_alarms.sh      # SETS=200, POSES=20, uniform poses
#   DRIFT="--sampling walk --step 0.1 --noise 0.02 --effect drift:sd=0.03,length=8" sh examples/check/drift_false_alarms.sh
set -eu
. examples/check/common.sh
SETS=${SETS:-200}
POSES=${POSES:-20}
DRIFT=${DRIFT:-"--sampling uniform --noise 0.02 --effect drift:sd=0.03,length=8"}

# shellcheck disable=SC2086
calibrate $DRIFT
grep -E '^(drift|noise floor)' "$W/fit.log" || true
s=0
while [ "$s" -lt "$SETS" ]; do
    # shellcheck disable=SC2086
    $CBD simulate --robot six $DRIFT --count "$POSES" --seed $((1000 + s)) --out "$W/fresh.csv" >/dev/null 2>&1
    check_fresh
    p_statistic_dof >>"$W/p.txt"
    s=$((s + 1))
done
echo "| scenario ($POSES poses per set: $DRIFT) | sets | changed at α = 0.05 | changed at α = 0.01 | mean statistic / dof |"
echo "|---|---|---|---|---|"
awk '{ a += ($1 < 0.05); b += ($1 < 0.01); r += $2 / $3; k++ }
    END { printf "| no change, drift sd 0.03 mm over 8 poses | %d | %d (%.3f) | %d (%.3f) | %.3f |\n", k, a, a / k, b, b / k, r / k }' "$W/p.txt"
