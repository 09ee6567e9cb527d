#!/usr/bin/env bash
# Fuzz smoke test: runs every cargo-fuzz target in fuzz/ for a few seconds from the committed seed
# corpus. Skips (exit 0) when cargo-fuzz or a nightly toolchain is missing; fails on a crash, a
# leak, a timeout or a build error of the fuzz crate.
#
#   FUZZ_SECONDS=5 (per target)   FUZZ_TARGETS="blob_eval csv_import"
#
# The committed corpus is only read: libFuzzer writes the inputs it finds into a scratch directory
# (the first corpus argument), so CI never grows fuzz/corpus/. Crash reproducers land in
# fuzz/artifacts/<target>/ (git-ignored); reproduce with
#   cargo +nightly fuzz run <target> fuzz/artifacts/<target>/crash-…
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR=never

seconds="${FUZZ_SECONDS:-5}"
targets="${FUZZ_TARGETS:-blob_eval csv_import}"

if ! command -v cargo >/dev/null 2>&1 || ! cargo +nightly --version >/dev/null 2>&1; then
    echo "fuzz-smoke: skipped — no nightly toolchain (rustup toolchain install nightly)"
    exit 0
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz-smoke: skipped — cargo-fuzz is not installed (cargo install cargo-fuzz)"
    exit 0
fi

cd fuzz
echo "== fuzz smoke: building targets ($(cargo +nightly --version))"
cargo +nightly fuzz build -O

scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
for t in $targets; do
    mkdir -p "$scratch/$t" "artifacts/$t"
    echo "== fuzz smoke: $t for ${seconds} s"
    # -timeout: one input taking longer than 10 s is a hang; -rss_limit_mb: 2 GB is a leak/blow-up.
    log="$scratch/$t.log"
    status=0
    cargo +nightly fuzz run -O "$t" "$scratch/$t" "$PWD/corpus/$t" -- \
        -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 >"$log" 2>&1 || status=$?
    grep -E '(INITED|DONE) |stat::number_of_executed_units|stat::peak_rss_mb' "$log" || true
    if [ "$status" -ne 0 ]; then
        tail -n 60 "$log"
        echo "fuzz-smoke: $t FAILED (exit $status); reproducer in fuzz/artifacts/$t/"
        exit 1
    fi
done
echo "fuzz-smoke: all targets ran ${seconds} s without a crash"
