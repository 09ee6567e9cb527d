#!/bin/sh
# Naming the change (issue 50 item 3): the simulated six-joint arm calibrated once on 300 poses
# (noise 0.02 mm), then SEEDS independent sets of POSES fresh random poses per planted change
# (`cbd simulate --effect`), each checked with `cbd check`. Per change: how often the check says
# "changed" (detection), how often the first named change is the planted one (named right, of the
# detected), how often it is named alone, the mean |size − truth| / se of the named size, and the
# mean p after the named change. "no change" counts false alarms and sets where something was
# named anyway. Run from the repository root:
#
#   sh examples/check/name_change.sh            # SEEDS=20, POSES=20
set -eu
. examples/check/common.sh
SEEDS=${SEEDS:-20}
POSES=${POSES:-20}
calibrate --sampling uniform --noise 0.02

# One table row: $1 label, $2 simulate flags, $3 the expected spelling ("" for none), $4 the
# planted size (as the check reports it: the offset, delta, |shift|, scale − 1), $5 check flags.
scenario() {
    s=0
    : >"$W/rows.txt"
    while [ "$s" -lt "$SEEDS" ]; do
        # shellcheck disable=SC2086
        $CBD simulate --robot six --sampling uniform --count "$POSES" --noise 0.02 --seed $((1000 + s)) $2 --out "$W/fresh.csv" >/dev/null 2>&1
        # shellcheck disable=SC2086
        check_fresh $5
        # verdict, the named effects (comma-joined), the first one's size and se, the p left after.
        awk '
            /"verdict"/ { gsub(/[",]/, "", $2); verdict = $2 }
            /"changes": \[/ { inside = 1 }
            inside && /^  \]/ { inside = 0 }
            inside && /"effect"/ { gsub(/[",]/, "", $2); names = names (names == "" ? "" : ",") $2 }
            inside && /"size"/ && size == "" { gsub(/,/, "", $2); size = $2 }
            inside && /"se"/ && se == "" { gsub(/,/, "", $2); se = $2 }
            /"after_change"/ { after = 1 }
            after && /"p_value"/ { gsub(/,/, "", $2); pafter = $2; after = 0 }
            END { printf "%s %s %s %s %s\n", verdict, (names == "" ? "-" : names), (size == "" ? "nan" : size), (se == "" ? "nan" : se), (pafter == "" ? "nan" : pafter) }
        ' "$W/check.json" >>"$W/rows.txt"
        s=$((s + 1))
    done
    awk -v label="$1" -v want="$3" -v truth="$4" '
        { k++; changed = ($1 == "changed"); d += changed
          if (changed) {
              split($2, named, ","); first = named[1]
              if (want == "") { any += ($2 != "-") }
              else if (first == want) { right++; alone += ($2 == want); z += ($3 - truth < 0 ? truth - $3 : $3 - truth) / $4; pa += $5 } } }
        END {
            if (want == "") printf "| %s | %d | %d (%.2f) | — | — | — | named anyway: %d |\n", label, k, d, d / k, any
            else printf "| %s | %d | %d (%.2f) | %d (%.2f) | %d | %.2f | %.2f |\n", label, k, d, d / k, right, (d ? right / d : 0), alone, (right ? z / right : 0), (right ? pa / right : 0) }
    ' "$W/rows.txt"
}

echo "| planted change ($POSES random poses per set) | sets | detected (α = 0.01) | named right (of detected) | named alone | mean \|size − truth\| / se | mean p after |"
echo "|---|---|---|---|---|---|---|"
scenario "none" "" "" 0 ""
scenario "joint_zero:joint=2,offset=1e-4 (rad)" "--effect joint_zero:joint=2,offset=1e-4" "joint_zero:joint=2" 1e-4 ""
scenario "joint_zero:joint=2,offset=5e-5 (rad)" "--effect joint_zero:joint=2,offset=5e-5" "joint_zero:joint=2" 5e-5 ""
scenario "joint_zero:joint=2,offset=1e-4, --register" "--effect joint_zero:joint=2,offset=1e-4" "joint_zero:joint=2" 1e-4 "--register"
scenario "base_shift:dx=0.05 (mm)" "--effect base_shift:dx=0.05" "base_shift" 0.05 ""
scenario "tool_shift:dz=0.05 (mm, flange)" "--effect tool_shift:dz=0.05" "tool_shift" 0.05 ""
scenario "link_length:link=3,delta=0.05 (mm)" "--effect link_length:link=3,delta=0.05" "link_length:link=3" 0.05 ""
scenario "link_length:link=3,delta=0.025 (mm)" "--effect link_length:link=3,delta=0.025" "link_length:link=3" 0.025 ""
scenario "link_twist:link=2,delta=1e-4 (rad)" "--effect link_twist:link=2,delta=1e-4" "link_twist:link=2" 1e-4 ""
scenario "length_scale:scale=1.0001" "--effect length_scale:scale=1.0001" "length_scale" 1e-4 ""
scenario "encoder_scale:joint=3,scale=1e-4" "--effect encoder_scale:joint=3,scale=1e-4" "encoder_scale:joint=3" 1e-4 ""
