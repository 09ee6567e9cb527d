#!/bin/sh
# `cbd check --update` (issue 50 item 4): the simulated six-joint arm calibrated once on 300 poses
# (noise 0.02 mm), `cbd plan --check 20` plans the check's poses for that blob, then per planted
# change SEEDS sets of those 20 poses measured on the changed arm (`cbd simulate --poses --effect`),
# each checked with `--update`. Per change: how often it is detected (α = 0.01), named right first,
# and updated; the mean error on 200 test poses of the changed arm of the parent blob, of the
# updated blobs, and of a full recalibration on 300 new poses of the changed arm (`cbd fit`, no
# flags); the ratio updated / full. The sizes are about twice the smallest `plan --check` says the
# check detects with 90 % power on the planned poses (printed first). Run from the repository root:
#
#   sh examples/check/update.sh                  # SEEDS=10
set -eu
. examples/check/common.sh
SEEDS=${SEEDS:-10}
POSES=20
calibrate --sampling uniform --noise 0.02
$CBD plan --model "$MODEL" --check "$POSES" --blob "$W/arm.blob" --out "$W/planned.csv" >"$W/plan.txt" 2>&1
grep -E '^(change|joint_zero:joint=2 |link_length:link=3 |base_shift|tool_shift|length_scale)' "$W/plan.txt"
echo

# The calibrated mean error of a `cbd eval --json` file (its first "mean": "calibrated" sorts first).
calibrated_mean() {
    awk -F': ' '/"mean"/ { gsub(/,/, "", $2); print $2; exit }' "$1"
}

# One table row: $1 the --effect spec, $2 the expected first named change.
scenario() {
    $CBD simulate --robot six --sampling uniform --count 200 --noise 0.02 --seed 77 --effect "$1" --out "$W/test.csv" >/dev/null 2>&1
    $CBD simulate --robot six --sampling uniform --count 300 --noise 0.02 --seed 2 --effect "$1" --out "$W/recal.csv" >/dev/null 2>&1
    $CBD fit --model "$MODEL" --data "$W/recal.csv" --out "$W/recal.blob" >/dev/null 2>&1
    $CBD eval --model "$MODEL" --blob "$W/recal.blob" --data "$W/test.csv" --json "$W/full.json" >/dev/null 2>&1
    $CBD eval --model "$MODEL" --blob "$W/arm.blob" --data "$W/test.csv" --json "$W/parent.json" >/dev/null 2>&1
    s=0
    : >"$W/rows.txt"
    while [ "$s" -lt "$SEEDS" ]; do
        $CBD simulate --robot six --poses "$W/planned.csv" --noise 0.02 --seed $((1000 + s)) --effect "$1" --out "$W/fresh.csv" >/dev/null 2>&1
        rm -f "$W/new.blob"
        check_fresh --update --out "$W/new.blob"
        verdict=$(sed -n 's/.*"verdict": "\([a-z]*\)".*/\1/p' "$W/check.json")
        first=$(sed -n 's/.*"effect": "\([^"]*\)".*/\1/p' "$W/check.json" | head -1)
        after=nan
        if [ -f "$W/new.blob" ]; then
            $CBD eval --model "$MODEL" --blob "$W/new.blob" --data "$W/test.csv" --json "$W/updated.json" >/dev/null 2>&1
            after=$(calibrated_mean "$W/updated.json")
        fi
        echo "$verdict ${first:--} $after" >>"$W/rows.txt"
        s=$((s + 1))
    done
    awk -v label="$1" -v want="$2" -v parent="$(calibrated_mean "$W/parent.json")" -v full="$(calibrated_mean "$W/full.json")" '
        { k++; d += ($1 == "changed"); right += ($1 == "changed" && $2 == want)
          if ($3 != "nan") { u++; sum += $3 } }
        END { m = (u ? sum / u : 0)
              printf "| %s | %d | %d | %d | %d | %.4f | %.4f | %.4f | %.3f |\n", label, k, d, right, u, parent, m, full, (u ? m / full : 0) }
    ' "$W/rows.txt"
}

echo "| planted change ($POSES planned poses per set) | sets | detected (α = 0.01) | named right first | updated | parent on test (mm) | updated on test (mm) | full recalibration (mm) | updated / full |"
echo "|---|---|---|---|---|---|---|---|---|"
scenario "joint_zero:joint=2,offset=1e-4" "joint_zero:joint=2"
scenario "base_shift:dx=0.07" "base_shift"
scenario "tool_shift:dz=0.07" "tool_shift"
scenario "link_length:link=3,delta=0.07" "link_length:link=3"
scenario "length_scale:scale=1.0001" "length_scale"
