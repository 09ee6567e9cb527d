# Sourced by the scripts in examples/check/ (run from the repository root): the binary, the model,
# a scratch directory removed on exit, and the steps every script takes.
CBD=${CBD:-target/release/cbd}
MODEL=examples/ur5/simulated-six.toml
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT

# The simulated six-joint arm measured at 300 poses (seed 1; `cbd simulate` flags "$@") and fitted
# with no flags: $W/cal.csv, $W/arm.blob, the fit's messages in $W/fit.log.
calibrate() {
    $CBD simulate --robot six "$@" --count 300 --seed 1 --out "$W/cal.csv" >/dev/null 2>&1
    $CBD fit --model "$MODEL" --data "$W/cal.csv" --out "$W/arm.blob" >"$W/fit.log" 2>&1
}

# `cbd check` of $W/fresh.csv against the blob (extra check flags "$@"), its JSON in $W/check.json;
# exit 3 ("changed") is a result here, not a failure.
check_fresh() {
    $CBD check --model "$MODEL" --blob "$W/arm.blob" --data "$W/fresh.csv" --json "$W/check.json" "$@" >/dev/null || [ $? -eq 3 ]
}

# The check's p, statistic and dof on one line.
p_statistic_dof() {
    for key in p_value statistic dof; do
        sed -n "s/.*\"$key\": \([^,]*\),*/\1/p" "$W/check.json"
    done | tr '\n' ' '
    echo
}
