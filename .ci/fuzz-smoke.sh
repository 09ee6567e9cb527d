#!/usr/bin/env bash
# Fuzz smoke test: runs every cargo-fuzz target in fuzz/ for a minute from the committed seed
# corpus. Installs a nightly toolchain and cargo-fuzz when missing (a fresh CI machine has
# neither); fails on a crash (panic, overflow, abort), a timeout, a build error of the fuzz crate,
# or a target that did not run.
#
#   FUZZ_SECONDS=60 (per target)   FUZZ_TARGETS="blob_eval csv_import model_urdf"   FUZZ_SANITIZER=none
#
# No sanitizer by default: the code the targets reach (blob decoding and evaluation, CSV import,
# model files and URDF) contains no `unsafe` of ours (the C API in cbd-ffi and two libc calls of the
# trainer's CLI are not fuzzed), so AddressSanitizer adds little to a smoke run and slows the build
# of the trainer's dependencies. FUZZ_SANITIZER=address for
# a thorough run.
#
# The committed corpus is only read: libFuzzer writes the inputs it finds into a scratch directory
# (the first corpus argument), so CI never grows fuzz/corpus/. Crash reproducers land in
# fuzz/artifacts/<target>/ (git-ignored); reproduce with
#   cargo +nightly fuzz run <target> fuzz/artifacts/<target>/crash-…
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR=never

seconds="${FUZZ_SECONDS:-60}"
targets="${FUZZ_TARGETS:-blob_eval csv_import model_urdf}"
sanitizer="${FUZZ_SANITIZER:-none}"

if ! cargo +nightly --version >/dev/null 2>&1; then
    echo "fuzz-smoke: installing a nightly toolchain"
    rustup toolchain install nightly --profile minimal
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz-smoke: installing cargo-fuzz"
    cargo install cargo-fuzz --locked
fi

cd fuzz
echo "== fuzz smoke: building targets ($(cargo +nightly --version))"
cargo +nightly fuzz build -O --sanitizer "$sanitizer"

scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
# fuzz_one TARGET: runs one target for $seconds and writes its verdict to $scratch/TARGET.verdict.
fuzz_one() {
    local t="$1" log="$scratch/$1.log" status=0 runs
    mkdir -p "$scratch/$t" "artifacts/$t"
    # -timeout: one input taking longer than 10 s is a hang; -rss_limit_mb: 2 GB is a leak/blow-up.
    cargo +nightly fuzz run -O --sanitizer "$sanitizer" "$t" "$scratch/$t" "$PWD/corpus/$t" -- \
        -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 >"$log" 2>&1 || status=$?
    if [ "$status" -ne 0 ]; then
        echo "FAILED (exit $status); reproducer in fuzz/artifacts/$t/" >"$scratch/$t.verdict"
        return
    fi
    # A target that ran no inputs did not test anything: fail rather than pass silently.
    runs="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)"
    if [ -z "$runs" ] || [ "$runs" -eq 0 ]; then
        echo "executed no inputs" >"$scratch/$t.verdict"
        return
    fi
    echo "ok $runs" >"$scratch/$t.verdict"
}
# libFuzzer runs one process per target: as many targets at once as there are cores, so each still
# has a core of its own for its $seconds (a 2-core machine runs three targets in two rounds, not three).
cores="$(nproc 2>/dev/null || echo 1)"
running=0
for t in $targets; do
    if [ "$running" -ge "$cores" ]; then
        wait -n || true
        running=$((running - 1))
    fi
    echo "== fuzz smoke: $t for ${seconds} s"
    fuzz_one "$t" &
    running=$((running + 1))
done
wait
failed=0
for t in $targets; do
    log="$scratch/$t.log"
    grep -E '(INITED|DONE) |stat::number_of_executed_units|stat::peak_rss_mb' "$log" || true
    verdict="$(cat "$scratch/$t.verdict" 2>/dev/null || echo "did not run")"
    case "$verdict" in
        ok\ *) echo "fuzz-smoke: $t executed ${verdict#ok } inputs in ${seconds} s" ;;
        *)
            tail -n 60 "$log" 2>/dev/null || true
            echo "fuzz-smoke: $t $verdict"
            failed=1
            ;;
    esac
done
[ "$failed" -eq 0 ] || exit 1
echo "fuzz-smoke: all targets ran ${seconds} s without a crash"
