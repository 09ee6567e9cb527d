#!/usr/bin/env bash
# The runtime from C (issue 16): cbd-ffi's static library and generated header, proven from C.
#
#   bash .ci/c-ffi.sh            # checks (after .ci/firmware.sh: reuses its blobs, host lines and Rust ELFs)
#   bash .ci/c-ffi.sh --write    # also replaces the "## Firmware from C (QEMU)" section of BENCHMARKS.md
#
# 1. Host: builds libcbd_ffi.a (cargo profile `ffi`: panic = "abort"), compiles examples/c with the
#    system C compiler; `check errors` (NULL pointers, short buffers, misaligned storage, corrupt
#    blobs get their codes); `eval_csv` on the demo blob and 3000 random configurations against
#    `cbd eval --json` (rows, extrapolating, calibrated mean/median/p99/max: equal floats); `check
#    lines` against `cbd-fw-host eval` (every position and Jacobian value's bits) for every test blob.
# 2. Cortex-M: libcbd_ffi.a for thumbv7em-none-eabihf with the panic-never feature (the panic
#    handler calls an undefined symbol); a link that keeps every exported function proves no panic
#    is reachable from C. examples/c/firmware/main.c (arm-none-eabi-gcc, no C library) per blob
#    (rr, six-effects), run under QEMU and compared bit for bit with the host runtime: the sp build
#    (f64 in software) on the M4 and the M7, the dp build (-C target-cpu=cortex-m7, the M7's
#    double-precision FPU) on the M7. CBD_C_FFI_VARIANTS=sp skips the dp build.
# 3. Cost: code size (ELF text − blob) and instructions per evaluation (SysTick ticks × 40 under
#    -icount shift=0, as .ci/firmware-cost.sh) against the Rust firmware of the same build variant,
#    blob and CPU; fails when the C firmware is more than 5 % larger or slower.
# The header is checked by `cargo test -p cbd-ffi` (test header_is_current), part of the host tests.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
FIRMWARE_LIB_ONLY=1 source "$ROOT/.ci/firmware.sh"
C_OUT="$ROOT/target/c-ffi"
write=0
[ "${1:-}" = "--write" ] && write=1
clog() { printf '[c-ffi] %s\n' "$*" >&2; }

fw_install
if ! command -v arm-none-eabi-gcc >/dev/null 2>&1; then
    clog "installing gcc-arm-none-eabi"
    sudo=""; [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends gcc-arm-none-eabi >/dev/null
fi
CC_HOST="${CC:-cc}"
mkdir -p "$C_OUT"
failures=0
summary=()
pass() { summary+=("PASS  $*"); }
fail() { summary+=("FAIL  $*"); failures=$((failures + 1)); }

# ---- host
# docs/guide/firmware.md shows examples/c/eval_csv.c in full: the same text.
if python3 - "$ROOT/docs/guide/firmware.md" "$ROOT/examples/c/eval_csv.c" <<'PY'
import sys
readme, src = (open(p).read() for p in sys.argv[1:3])
sys.exit(0 if "```c\n" + src + "```" in readme else 1)
PY
then pass "the guide's C host example is examples/c/eval_csv.c"; else fail "the guide's C host example (docs/guide/firmware.md) differs from examples/c/eval_csv.c"; fi
clog "building libcbd_ffi.a (host, profile ffi)"
(cd "$ROOT" && cargo build -q -p cbd-ffi --profile ffi)
HOST_LIB="$ROOT/target/ffi/libcbd_ffi.a"
CFLAGS_HOST="-O2 -std=c11 -Wall -Wextra -Werror -ffp-contract=off -I$ROOT/ffi/include -I$ROOT/examples/c"
# shellcheck disable=SC2086
$CC_HOST $CFLAGS_HOST "$ROOT/examples/c/eval_csv.c" "$HOST_LIB" -lm -o "$C_OUT/eval_csv"
# shellcheck disable=SC2086
$CC_HOST $CFLAGS_HOST "$ROOT/examples/c/check.c" "$HOST_LIB" -lm -o "$C_OUT/check"

[ -x "$HOST" ] && [ -f "$OUT/blobs/rr.blob" ] || fw_host_and_blobs
if "$C_OUT/check" errors "$OUT/blobs/rr.blob" >"$C_OUT/errors.txt" 2>&1; then
    pass "C host: $(grep -c '^ok' "$C_OUT/errors.txt") error-path checks (NULL, short buffers, misaligned, corrupt blob) return their codes"
else
    fail "C host error paths (see $C_OUT/errors.txt)"
fi

CBD="$ROOT/target/release/cbd"
[ -x "$CBD" ] || (cd "$ROOT" && cargo build -q --release -p cbd-trainer --bin cbd)
"$CBD" demo --quiet --out "$C_OUT/demo.blob" >"$C_OUT/demo.log" 2>&1
"$CBD" simulate --sampling uniform --count 3000 --seed 7 --out "$C_OUT/test.csv" >>"$C_OUT/demo.log" 2>&1
"$CBD" eval --blob "$C_OUT/demo.blob" --data "$C_OUT/test.csv" --json "$C_OUT/eval-rust.json" >>"$C_OUT/demo.log" 2>&1
"$C_OUT/eval_csv" "$C_OUT/demo.blob" "$C_OUT/test.csv" >"$C_OUT/eval-c.json"
if python3 - "$C_OUT/eval-rust.json" "$C_OUT/eval-c.json" <<'PY'
import json, sys
r, c = (json.load(open(p)) for p in sys.argv[1:3])
keys = ["mean", "median", "p99", "max"]
ok = r["rows"] == c["rows"] and r["extrapolating"] == c["extrapolating"] and all(r["calibrated"][k] == c["calibrated"][k] for k in keys)
print("rust", r["rows"], r["extrapolating"], [r["calibrated"][k] for k in keys], file=sys.stderr)
print("c   ", c["rows"], c["extrapolating"], [c["calibrated"][k] for k in keys], file=sys.stderr)
sys.exit(0 if ok else 1)
PY
then
    pass "C host eval_csv = cbd eval --json on the demo blob, 3000 rows (mean, median, p99, max, extrapolating: equal)"
else
    fail "C host eval_csv differs from cbd eval --json ($C_OUT/eval-c.json, $C_OUT/eval-rust.json)"
fi

BLOBS="rr rr256 six six-effects"
for name in $BLOBS; do
    host="$OUT/host-$name.txt"
    [ -s "$host" ] || "$HOST" eval "$OUT/blobs/$name.blob" >"$host"
    # The C programs evaluate; the host's `qc` lines (compensation) are checked through C by the
    # cbd-ffi test `compensate_gives_the_runtimes_bits_and_its_errors`, not here.
    if "$C_OUT/check" lines "$OUT/blobs/$name.blob" >"$C_OUT/host-c-$name.txt" && diff -q "$C_OUT/host-c-$name.txt" <(grep -v '^qc' "$host") >/dev/null; then
        pass "C host: $name blob, $(grep -c '^q[0-9]' "$host") configurations bit-identical to the Rust runtime (cbd-fw-host eval)"
    else
        fail "C host: $name blob differs from cbd-fw-host eval ($C_OUT/host-c-$name.txt)"
    fi
done

# ---- Cortex-M
# Two builds, as the Rust firmware's: "sp" (thumbv7em-none-eabihf defaults: single-precision FPU,
# f64 in software; runs on the M4 and the M7) and "dp" (-C target-cpu=cortex-m7 / -mcpu=cortex-m7
# -mfpu=fpv5-d16: the M7's double-precision FPU; M7 only; its own cargo target directory).
# arm_lib VARIANT -> builds and prints the path of libcbd_ffi.a
arm_lib() {
    local variant="$1" dir="$ROOT/target" flags=""
    [ "$variant" = dp ] && { dir="$ROOT/target/ffi-cortex-m7"; flags="-C target-cpu=cortex-m7"; }
    clog "building libcbd_ffi.a (thumbv7em-none-eabihf, profile ffi, panic-never, $variant)"
    (cd "$ROOT" && CARGO_TARGET_DIR="$dir" RUSTFLAGS="$flags" cargo rustc -q -p cbd-ffi --profile ffi \
        --target thumbv7em-none-eabihf --features panic-never --crate-type staticlib)
    echo "$dir/thumbv7em-none-eabihf/ffi/libcbd_ffi.a"
}
CFLAGS_ARM="-mthumb -mfloat-abi=hard -O2 -std=c11 -Wall -Wextra -Werror -ffp-contract=off
 -ffunction-sections -fdata-sections -nostdlib -Wl,--gc-sections -Wl,-z,noexecstack -T $ROOT/examples/c/firmware/link.ld
 -I$ROOT/ffi/include -I$ROOT/examples/c"
cpu_flags() { case "$1" in dp*) echo "-mcpu=cortex-m7 -mfpu=fpv5-d16" ;; *) echo "-mcpu=cortex-m4 -mfpu=fpv4-sp-d16" ;; esac; }
# arm_link BLOB_NAME VARIANT LIB [extra gcc arguments] -> the ELF's path
arm_link() {
    local name="$1" variant="$2" lib="$3" bytes elf
    shift 3
    bytes="$("$C_OUT/check" size "$OUT/blobs/$name.blob")"
    elf="$C_OUT/fw-$name-$variant.elf"
    # shellcheck disable=SC2086
    arm-none-eabi-gcc $(cpu_flags "$variant") $CFLAGS_ARM "$@" -DCBD_BLOB_PATH="\"$OUT/blobs/$name.blob\"" -DCBD_STORAGE_BYTES="$bytes" \
        "$ROOT/examples/c/firmware/main.c" "$lib" -lgcc -o "$elf"
    echo "$elf"
}

# The RR blob (Heun × 5) and the 6-joint blob with all four physical effects; the runs of one ELF
# in parallel (QEMU is single-threaded).
VARIANTS="${CBD_C_FFI_VARIANTS:-sp dp}"
for variant in $VARIANTS; do
    lib="$(arm_lib "$variant")"
    # Panic-never: every exported function kept as a root of the link (and no reference to the
    # panic-never handler's undefined symbol anywhere in the library).
    roots=$(grep -o '\bcbd_[a-z_]*(' "$ROOT/ffi/include/cbd.h" | tr -d '(' | sort -u | sed 's/^/-Wl,--undefined=/' | tr '\n' ' ')
    # shellcheck disable=SC2086
    if arm_link rr "$variant-all-exports" "$lib" $roots >"$C_OUT/panic-never-$variant.log" 2>&1 \
        && ! arm-none-eabi-nm -u "$lib" 2>/dev/null | grep -q cbd_ffi_panic_is_reachable; then
        pass "panic-never ($variant): the thumb library links with all $(echo "$roots" | wc -w) exported functions kept (no reachable panic)"
    else
        fail "panic-never ($variant): a panic is reachable from an exported function (see $C_OUT/panic-never-$variant.log)"
    fi
    cpus="m4 m7"
    [ "$variant" = dp ] && cpus="m7"
    for name in rr six-effects; do
        elf="$(arm_link "$name" "$variant" "$lib")"
        declare -A pid=()
        for cpu in $cpus; do
            fw_run "$elf" "$cpu" "$C_OUT/fw-$name-$variant-$cpu.txt" &
            pid[$cpu]=$!
        done
        for cpu in $cpus; do
            run="$C_OUT/fw-$name-$variant-$cpu.txt"
            if wait "${pid[$cpu]}" && diff <(grep '^q' "$run") <(grep -v '^qc' "$OUT/host-$name.txt") >"$C_OUT/diff-$name-$variant-$cpu.txt"; then
                pass "C firmware ($variant) on $cpu: $name blob, $(grep -c '^q' "$run") configurations bit-identical to the host runtime"
            else
                fail "C firmware ($variant) on $cpu: $name blob (see $run, $C_OUT/diff-$name-$variant-$cpu.txt)"
            fi
        done
    done
done

# ---- cost against the Rust firmware, same build variant (ELFs and runs from .ci/firmware.sh when present)
if command -v llvm-size >/dev/null 2>&1; then SIZE=llvm-size; else SIZE=arm-none-eabi-size; fi
mean() { awk '$1 ~ /^t[0-9]/ {s += $2; n++} END {printf "%.0f", s * 40 / n}' "$1"; }
minmax() { awk '$1 ~ /^t[0-9]/ {v = $2 * 40; if (min == "" || v < min) min = v; if (v > max) max = v} END {print min, max}' "$1"; }
rows=()
worst=-100
for variant in $VARIANTS; do
    cpu=m4
    [ "$variant" = dp ] && cpu=m7
    for name in rr six-effects; do
        rust_elf="$OUT/elf/$name-$variant.elf"
        rust_run="$OUT/fw-$name-$variant-$cpu.txt"
        [ -f "$rust_run" ] || rust_run="$OUT/cost-$name-$variant-$cpu.txt"   # .ci/firmware-cost.sh's run of the same ELF
        if [ ! -f "$rust_elf" ] || [ ! -f "$rust_run" ]; then
            rust_elf="$(fw_build "$name" "$variant")"
            rust_run="$OUT/fw-$name-$variant-$cpu.txt"
            fw_run "$rust_elf" "$cpu" "$rust_run"
        fi
        c_run="$C_OUT/fw-$name-$variant-$cpu.txt"
        blob_bytes=$(stat -c %s "$OUT/blobs/$name.blob")
        c_text=$($SIZE "$C_OUT/fw-$name-$variant.elf" | awk 'NR == 2 {print $1}')
        r_text=$($SIZE "$rust_elf" | awk 'NR == 2 {print $1}')
        c_mean=$(mean "$c_run"); r_mean=$(mean "$rust_run")
        read -r c_min c_max < <(minmax "$c_run")
        read -r r_min r_max < <(minmax "$rust_run")
        c_code=$((c_text - blob_bytes)); r_code=$((r_text - blob_bytes))
        d_code=$(awk -v c="$c_code" -v r="$r_code" 'BEGIN {printf "%+.2f", 100 * (c - r) / r}')
        d_instr=$(awk -v c="$c_mean" -v r="$r_mean" 'BEGIN {printf "%+.3f", 100 * (c - r) / r}')
        model="RR, Heun × 5"; [ "$name" = six-effects ] && model="6-joint, Heun × 5, 4 effects"
        rows+=("| $model | $cpu | $variant | $blob_bytes | $r_code | $c_code | $d_code % | $r_min–$r_max ($r_mean) | $c_min–$c_max ($c_mean) | $d_instr % |")
        for d in $d_code $d_instr; do
            worst=$(awk -v w="$worst" -v d="$d" 'BEGIN {print (d > w) ? d : w}')
        done
    done
done
if awk -v w="$worst" 'BEGIN {exit !(w < 5)}'; then
    pass "C firmware overhead vs the Rust firmware: at most $worst % (code size, instructions per evaluation; limit 5 %)"
else
    fail "C firmware overhead vs the Rust firmware: $worst % (limit 5 %)"
fi

table="$(
    echo "The C firmware (\`examples/c/firmware/main.c\`, arm-none-eabi-gcc -O2, no C library, linked against \`libcbd_ffi.a\` built for"
    echo "thumbv7em-none-eabihf with cargo profile \`ffi\`: opt-level 3, fat LTO, panic = \"abort\", feature panic-never) against the"
    echo "Rust firmware (\`examples/firmware\`) of the same build on the same blob and the same 128 configurations under QEMU:"
    echo "sp = thumbv7em-none-eabihf defaults (f64 in software; gcc -mcpu=cortex-m4 -mfpu=fpv4-sp-d16), on the M4; dp ="
    echo "\`-C target-cpu=cortex-m7\` (the M7's double-precision FPU; gcc -mcpu=cortex-m7 -mfpu=fpv5-d16), on the M7."
    echo "Code = ELF text − blob (whole firmware: runtime, decoder, soft-float, startup, printing). Instructions per evaluation ="
    echo "SysTick ticks × 40 under \`-icount shift=0\` (±40), min–max (mean); the C figure includes the \`cbd_evaluate\` call"
    echo "(argument checks, copying position and Jacobian out). Both print the same bits (the C sp build runs on the M4 and the M7)."
    echo "The C firmware's code is smaller: it prints hex digits with a few lines of C where the Rust firmware formats with"
    echo "core::fmt (our reading; the runtime is compiled with the same settings, opt-level 3 and fat LTO, in both)."
    echo "Produced by \`bash .ci/c-ffi.sh --write\`."
    echo
    echo "| model | CPU | build | blob bytes | Rust code bytes | C code bytes | code Δ | Rust instr/eval | C instr/eval | instr Δ |"
    echo "|---|---|---|---|---|---|---|---|---|---|"
    printf '%s\n' "${rows[@]}"
)"
echo "$table"

if [ "$write" = 1 ]; then
    bench="$ROOT/BENCHMARKS.md"
    section="$(printf '## Firmware from C (QEMU)\n\n%s\n' "$table")"
    SECTION="$section" awk '
        BEGIN { s = ENVIRON["SECTION"]; done = 0; skip = 0 }
        /^## / { if (skip) skip = 0 }
        /^## Firmware from C \(QEMU\)[[:space:]]*$/ { print s; print ""; skip = 1; done = 1; next }
        !skip { print }
        END { if (!done) { print ""; print s } }
    ' "$bench" >"$bench.tmp"
    mv "$bench.tmp" "$bench"
    clog "wrote the Firmware from C (QEMU) section of $bench"
fi

echo "== C checks (host and QEMU, bits against the Rust runtime) =="
printf '%s\n' "${summary[@]}"
if [ "$failures" -ne 0 ]; then
    echo "C checks: $failures failed"
    exit 1
fi
echo "C checks: passed"
