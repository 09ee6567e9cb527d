#!/usr/bin/env bash
# Five-fold cross-validation of every method of `cbd compare` on the real UR5 measurements
# (train.csv and test.csv merged, 1020 rows; fold k holds out the rows whose index mod 5 is k, or
# with FOLDS=blocked the k-th contiguous fifth of the rows in measurement order: no held-out pose
# then has a training neighbour in time, whose drift it shares — issue 49), and whether what `cbd fit` writes by default (the row `compare` marks with *) is within one
# standard error of the best other method's mean (issue 38).
#
#   [FOLDS=interleaved|blocked|both] [BENCHMARKS=BENCHMARKS.md] bash examples/ur5/cross_validate.sh [CBD] [OUT_DIR]
#
# CBD defaults to target/release/cbd; OUT_DIR (default target/ur5-cv) gets each fold's files and
# compare JSON and summary.json. Exit status 0 when the default is within one standard error.
# FOLDS=both runs the blocked folds, then the interleaved ones (OUT_DIR/blocked, OUT_DIR/interleaved);
# with BENCHMARKS=FILE it then rewrites FILE's table between the markers
# `<!-- ur5-cv: begin -->` and `<!-- ur5-cv: end -->` (issue 49 item 4), blocked first.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cbd="${1:-$here/../../target/release/cbd}"
out="${2:-$here/../../target/ur5-cv}"
mkdir -p "$out"
folds="${FOLDS:-interleaved}"
case "$folds" in interleaved|blocked|both) ;; *) echo "FOLDS must be interleaved, blocked or both, not '$folds'" >&2; exit 2 ;; esac
if [ "$folds" = both ]; then
    status=0
    FOLDS=blocked bash "$0" "$cbd" "$out/blocked" || status=1
    FOLDS=interleaved bash "$0" "$cbd" "$out/interleaved" || status=1
    if [ -n "${BENCHMARKS:-}" ]; then
        python3 "$here/benchmarks_table.py" "$out/blocked/summary.json" "$out/interleaved/summary.json" "$BENCHMARKS" "$(uname -m), $(nproc) cores"
    fi
    exit "$status"
fi
python3 - "$here/train.csv" "$here/test.csv" "$out" "$folds" <<'PY'
import sys
train, test, out, folds = sys.argv[1:5]
rows, header = [], None
for path in (train, test):
    with open(path) as f:
        lines = f.read().splitlines()
    header = header or lines[0]
    rows += [l for l in lines[1:] if l.strip()]
def held_out(i, k):
    return i % 5 == k if folds == "interleaved" else i * 5 // len(rows) == k
for k in range(5):
    held = [r for i, r in enumerate(rows) if held_out(i, k)]
    kept = [r for i, r in enumerate(rows) if not held_out(i, k)]
    for name, part in (("train", kept), ("test", held)):
        with open(f"{out}/fold{k}-{name}.csv", "w") as f:
            f.write("\n".join([header] + part) + "\n")
print(f"{len(rows)} rows in 5 {folds} folds", file=sys.stderr)
PY
for k in 0 1 2 3 4; do
    echo "fold $k" >&2
    "$cbd" compare --model "$here/ur5.toml" --train "$out/fold$k-train.csv" --test "$out/fold$k-test.csv" \
        --json "$out/fold$k.json" > "$out/fold$k.txt"
done
python3 - "$out" <<'PY'
import json, math, sys
out = sys.argv[1]
folds = [json.load(open(f"{out}/fold{k}.json")) for k in range(5)]
names = list(folds[0]["methods"])
written = [f["default_fit"]["method"] for f in folds]
stats = {}
for n in names:
    v = [f["methods"][n]["mean"] for f in folds]
    mean = sum(v) / len(v)
    se = math.sqrt(sum((x - mean) ** 2 for x in v) / (len(v) - 1) / len(v))
    stats[n] = (mean, se, v)
# What `cbd fit` writes on each fold (cbd or dh+cbd, by its own choice), as one method.
default = [f["methods"][w]["mean"] for f, w in zip(folds, written)]
d_mean = sum(default) / 5
d_se = math.sqrt(sum((x - d_mean) ** 2 for x in default) / 4 / 5)
print(f"{'method':<14} {'mean (mm)':>10} {'s.e.':>8}   per fold")
for n in names:
    m, se, v = stats[n]
    print(f"{n:<14} {m:>10.4f} {se:>8.4f}   " + " ".join(f"{x:.4f}" for x in v))
print(f"{'cbd fit':<14} {d_mean:>10.4f} {d_se:>8.4f}   " + " ".join(f"{x:.4f}" for x in default) + f"   (writes: {', '.join(written)})")
others = [n for n in names if n not in set(written)] if len(set(written)) == 1 else [n for n in names if n not in ("cbd", "dh+cbd")]
best = min(others, key=lambda n: stats[n][0])
bound = stats[best][0] + stats[best][1]
ok = d_mean <= bound
print(f"best other method: {best} {stats[best][0]:.4f} ± {stats[best][1]:.4f} mm; cbd fit's default {d_mean:.4f} mm: "
      + ("within one standard error" if ok else "NOT within one standard error"))
json.dump({"methods": {n: {"mean": stats[n][0], "se": stats[n][1], "folds": stats[n][2]} for n in names},
           "default_fit": {"mean": d_mean, "se": d_se, "folds": default, "writes": written},
           "best_other": best, "within_one_se": ok}, open(f"{out}/summary.json", "w"), indent=1)
sys.exit(0 if ok else 1)
PY
