#!/usr/bin/env bash
# Firmware check (issue 5): the runtime on a Cortex-M under QEMU, bit-identical to the host.
#
#   bash .ci/firmware.sh
#
# Installs what is missing (qemu-system-arm, the thumbv7em-none-eabihf target), checks that the
# runtime builds for the thumb target (no_std proof), builds the host tool (examples/fw-host) and the
# test blobs, builds the firmware (examples/firmware) once per blob, runs it on QEMU's Cortex-M4
# (mps2-an386) and Cortex-M7 (mps2-an500), and compares every printed f64 with the host runtime's,
# bit for bit. Also runs a Cortex-M7 build that uses the M7's double-precision FPU
# (-C target-cpu=cortex-m7), and an f32 build (the runtime's `f32` feature) against the host
# runtime built with the same feature. Exits non-zero on any difference.
#
# Each run also reports the query's stack high-water mark (painted stack) and checks it fits the RAM
# memory.x leaves (sized to the STM32F767ZI: 512 KB); the figures go to $OUT/stack.txt.
#
# Last, "panic-never" builds, one per variant (sp, dp, f32; feature panic-never): the panic handler calls an
# undefined symbol, so the firmware links only if the optimiser removed every panic path (runtime,
# protocol decoding, printing, stack painting). A reachable panic fails the check (CBD_FW_REQUIRE_PANIC_NEVER=0
# reports it without failing); examples/firmware/find-panics.py then lists where the panics are.
#
# Sourced with FIRMWARE_LIB_ONLY=1 (by .ci/firmware-cost.sh) it only defines the helpers.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
FW_DIR="$ROOT/examples/firmware"
OUT="${CBD_FW_OUT:-$ROOT/target/firmware-check}"
HOST="$ROOT/target/debug/cbd-fw-host"
QEMU_TIMEOUT="${CBD_FW_QEMU_TIMEOUT:-900}"

log() { printf '[firmware] %s\n' "$*" >&2; }

fw_install() {
    if ! command -v qemu-system-arm >/dev/null 2>&1; then
        log "installing qemu-system-arm"
        local sudo=""
        [ "$(id -u)" -eq 0 ] || sudo="sudo"
        $sudo apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq qemu-system-arm >/dev/null
    fi
    if ! rustup target list --installed | grep -qx thumbv7em-none-eabihf; then
        log "adding the thumbv7em-none-eabihf target"
        rustup target add thumbv7em-none-eabihf
    fi
}

# Host tool and blobs (deterministic bytes).
fw_host_and_blobs() {
    log "building cbd-fw-host"
    (cd "$ROOT" && cargo build -q -p cbd-fw-host)
    mkdir -p "$OUT"
    "$HOST" make-blobs "$OUT/blobs" >&2
}

# The host tool with the runtime's f32 feature, in its own target directory: a `-p` selection, so
# cargo's feature unification never hands f32 to the trainer.
HOST_F32="$ROOT/target/f32-host/debug/cbd-fw-host"
fw_host_f32() {
    log "building cbd-fw-host (runtime feature f32)"
    (cd "$ROOT" && CARGO_TARGET_DIR="$ROOT/target/f32-host" cargo build -q -p cbd-fw-host --features cbd-runtime/f32)
}

# fw_build BLOB_NAME VARIANT  ->  prints the path of a copy of the ELF.
# VARIANT: "sp"  (target default: single-precision FPU, f64 in software; runs on M4 and M7)
#          "dp"  (-C target-cpu=cortex-m7: the M7's double-precision FPU; M7 only)
#          "f32" (target default, the runtime's f32 feature: evaluation in f32 on the FPU)
fw_build() {
    local name="$1" variant="$2" blob storage flags target_dir features=""
    blob="$OUT/blobs/$name.blob"
    storage="$("$HOST" info "$blob" | awk '{print $4}')"
    target_dir="$FW_DIR/target/$variant"
    case "$variant" in
        sp) flags="-C link-arg=-Tlink.x" ;;
        dp) flags="-C link-arg=-Tlink.x -C target-cpu=cortex-m7" ;;
        f32) flags="-C link-arg=-Tlink.x"; features="--features f32" ;;
        *) log "unknown variant $variant"; return 1 ;;
    esac
    # Chains beyond 7 joints need the runtime's `long-chains` build (16 joints, larger stack arrays).
    # It shares the variant's target directory: cargo keeps each feature set's artifacts apart (their
    # own metadata hash), so the dependencies compile once per variant and the builds do not undo
    # each other.
    if [ "$("$HOST" info "$blob" | awk '{print $2}')" -gt 7 ]; then
        features="$features --features long-chains"
    fi
    log "building firmware: blob $name, variant $variant, storage $storage values"
    # shellcheck disable=SC2086
    (cd "$FW_DIR" && CARGO_TARGET_DIR="$target_dir" RUSTFLAGS="$flags" CBD_BLOB="$blob" CBD_STORAGE_LEN="$storage" \
        cargo build -q --release $features)
    mkdir -p "$OUT/elf"
    cp "$target_dir/thumbv7em-none-eabihf/release/cbd-firmware" "$OUT/elf/$name-$variant.elf"
    echo "$OUT/elf/$name-$variant.elf"
}

# fw_run ELF CPU(m4|m7) OUTFILE: runs under QEMU with -icount shift=0 (SysTick: 1 tick = 40 instructions).
fw_run() {
    local elf="$1" cpu="$2" outfile="$3" machine
    case "$cpu" in
        m4) machine="-machine mps2-an386 -cpu cortex-m4" ;;
        m7) machine="-machine mps2-an500 -cpu cortex-m7" ;;
    esac
    # shellcheck disable=SC2086
    if ! timeout "$QEMU_TIMEOUT" qemu-system-arm $machine -nographic -monitor none \
        -semihosting-config enable=on,target=native -icount shift=0 -kernel "$elf" >"$outfile" 2>&1 </dev/null; then
        log "QEMU failed ($cpu, $elf):"; tail -5 "$outfile" >&2; return 1
    fi
    grep -qx done "$outfile" || { log "firmware did not finish ($cpu, $elf)"; tail -5 "$outfile" >&2; return 1; }
}

# fw_stack ELF RUNFILE: the query's stack high-water mark (the firmware's `stack BYTES` line,
# measured by painting) against the RAM left for the stack in that ELF (from the end of the statics,
# `__sheap`, to the top of RAM, `_stack_start`; memory.x gives the STM32F767ZI's 512 KB). Prints
# "USED FREE" and fails when the query does not fit.
fw_stack() {
    local elf="$1" run="$2" used top bottom free
    used="$(sed -n 's/^stack \([0-9]*\)$/\1/p' "$run")"
    [ -n "$used" ] || { log "no stack line in $run"; return 1; }
    top="$(nm "$elf" | awk '$3 == "_stack_start" {print $1}')"
    bottom="$(nm "$elf" | awk '$3 == "__sheap" {print $1}')"
    free=$(( 0x$top - 0x$bottom ))
    echo "$used $free"
    [ "$used" -le "$free" ]
}

if [ "${FIRMWARE_LIB_ONLY:-0}" = 1 ]; then
    return 0 2>/dev/null || exit 0
fi

fw_install
log "runtime builds for thumbv7em-none-eabihf (no_std, no heap)"
(cd "$ROOT/runtime" && cargo build -q --target thumbv7em-none-eabihf --release)
fw_host_and_blobs
fw_host_f32

# six-effects (the 6-joint blob with all four physical effect types) runs sp on the M4 and dp on
# the M7 only, to keep the check short. rr-ws and six-ws hold the fields in the kernels' own basis
# (format 5, docs/DESIGN.md §11): the runtime evaluates the expansion instead of the kernel form.
# chain10 (10 joints, the longest chain the firmware check holds) and six-points (three tool points,
# format 6: every query also prints the tool frame and its Jacobian, `qp` lines) run like six-effects.
# six-c holds the configuration-dependent task field (format 8, docs/DESIGN.md §16, Euler × 1).
BLOBS="rr rr256 six six-effects rr-ws six-ws chain10 six-points six-c"
variants_of() { case "$1" in six-effects | chain10 | six-points) echo "sp dp" ;; *) echo "sp dp f32" ;; esac; }
# cpus_of BLOB VARIANT
cpus_of() {
    if [ "$2" = dp ]; then echo m7; return; fi
    case "$1" in six-effects | chain10 | six-points) [ "$2" = sp ] && { echo m4; return; } ;; esac
    echo "m4 m7"
}

rm -f "$OUT"/summary-*.txt "$OUT"/stack-*.txt "$OUT/stack.txt" "$OUT"/fw-*.txt
# The host's lines for every blob, and what they hold: $OUT/host-NAME.count is "VALUES ERRORS".
host_summary=()
for name in $BLOBS; do
    "$HOST" eval "$OUT/blobs/$name.blob" >"$OUT/host-$name.txt"
    "$HOST_F32" eval "$OUT/blobs/$name.blob" >"$OUT/host-$name-f32.txt"
    values=$(awk '$1 ~ /^q/ && $2 != "error" {n += NF - 2} END {print n + 0}' "$OUT/host-$name.txt")
    errors=$(grep -c ' error$' "$OUT/host-$name.txt" || true)
    echo "$values $errors" >"$OUT/host-$name.count"
    [ "$values" -ne 0 ] || host_summary+=("FAIL  $name blob: the host printed no values")
done

# run_on_cpu NAME VARIANT CPU ELF: runs one firmware on one CPU and compares its bits and stack,
# writing PASS/FAIL lines to $OUT/summary-NAME-VARIANT-CPU.txt.
run_on_cpu() {
    local name="$1" variant="$2" cpu="$3" elf="$4" run host values errors stack summary="$OUT/summary-$1-$2-$3.txt"
    run="$OUT/fw-$name-$variant-$cpu.txt"
    host="$OUT/host-$name.txt"
    [ "$variant" = f32 ] && host="$OUT/host-$name-f32.txt"
    read -r values errors <"$OUT/host-$name.count"
    {
        if fw_run "$elf" "$cpu" "$run" && diff <(grep '^q' "$run") "$host" >"$OUT/diff-$name-$variant-$cpu.txt"; then
            echo "PASS  $name blob  ${variant} build on $cpu: $values values bit-identical to the host's ($errors evaluation errors)"
            if stack="$(fw_stack "$elf" "$run")"; then
                echo "PASS  $name blob  ${variant} build on $cpu: a query's stack ${stack% *} bytes, ${stack#* } bytes free for it"
                echo "$name $variant $cpu $stack" >"$OUT/stack-$name-$variant-$cpu.txt"
            else
                echo "FAIL  $name blob  ${variant} build on $cpu: the query's stack does not fit the RAM left (${stack:-no figure})"
            fi
        else
            echo "FAIL  $name blob  ${variant} build on $cpu: see $OUT/diff-$name-$variant-$cpu.txt"
        fi
    } >"$summary"
}

# Panic-free at link level, for every build (sp, dp, f32): the variants compile different code
# (software f64, the M7's FPU, the f32 feature), so one panic-free build proves nothing of the others.
rr_storage="$("$HOST" info "$OUT/blobs/rr.blob" | awk '{print $4}')"
# panic_never VARIANT: builds the rr blob's firmware with the panic handler that does not link, in
# the variant's target directory (the dependencies are the ones its other builds compiled), runs it,
# and writes its line to $OUT/summary-panic-never-VARIANT.txt.
panic_never() {
    local variant="$1" status=0 run summary="$OUT/summary-panic-never-$1.txt"
    local dir="$FW_DIR/target/$variant" pn_log="$OUT/panic-never-$1.log"
    local flags="-C link-arg=-Tlink.x" features="panic-never" cpu=m4 host="$OUT/host-rr.txt"
    case "$variant" in
        dp) flags="$flags -C target-cpu=cortex-m7"; cpu=m7 ;;
        f32) features="panic-never,f32"; host="$OUT/host-rr-f32.txt" ;;
    esac
    log "building the panic-never firmware (rr blob, $variant)"
    (cd "$FW_DIR" && CARGO_TARGET_DIR="$dir" RUSTFLAGS="$flags" CBD_BLOB="$OUT/blobs/rr.blob" \
        CBD_STORAGE_LEN="$rr_storage" cargo build -q --release --no-default-features --features "$features") \
        >"$pn_log" 2>&1 || status=$?
    if [ "$status" = 0 ]; then
        cp "$dir/thumbv7em-none-eabihf/release/cbd-firmware" "$OUT/elf/rr-panic-never-$variant.elf"
        run="$OUT/fw-rr-panic-never-$variant-$cpu.txt"
        if fw_run "$OUT/elf/rr-panic-never-$variant.elf" "$cpu" "$run" && diff <(grep '^q' "$run") "$host" >/dev/null; then
            echo "PASS  panic-never $variant build links (no reachable panic in runtime, decoder or printing) and is bit-identical on $cpu" >"$summary"
        else
            echo "FAIL  panic-never $variant build linked but its output differs (see $run)" >"$summary"
        fi
    elif grep -q 'undefined symbol: cbd_firmware_panic_is_reachable' "$pn_log"; then
        # Where are the panics? (same code and flags, with the ordinary panic handler)
        if command -v llvm-objdump >/dev/null 2>&1 && command -v llvm-nm >/dev/null 2>&1 && command -v python3 >/dev/null 2>&1; then
            python3 "$FW_DIR/find-panics.py" "$OUT/elf/rr-$variant.elf" >"$OUT/panic-sites-$variant.txt" 2>&1 || true
            log "panic sites: $OUT/panic-sites-$variant.txt"
        fi
        if [ "${CBD_FW_REQUIRE_PANIC_NEVER:-1}" = 1 ]; then
            echo "FAIL  panic-never $variant build: a panic is reachable (see $pn_log)" >"$summary"
        else
            echo "INFO  panic-never $variant build: a panic is reachable (see $OUT/panic-sites-$variant.txt)" >"$summary"
        fi
    else
        echo "FAIL  panic-never $variant build failed to compile (see $pn_log)" >"$summary"
    fi
}

# One pipeline per variant, the three side by side: each builds its blobs in order in its own target
# directory, then its panic-never build; each blob's QEMU runs start as soon as its firmware is built.
# A fat-LTO build with one codegen unit and a QEMU run each keep one core busy, so a 2-core machine
# stays busy throughout (builds and runs are all of this check's time). A failed build stops the
# check, as it did one at a time.
variant_pipeline() {
    local variant="$1" name elf cpu runs=()
    for name in $BLOBS; do
        case " $(variants_of "$name") " in *" $variant "*) ;; *) continue ;; esac
        elf="$(fw_build "$name" "$variant")" || { log "building the firmware for blob $name ($variant) failed"; return 1; }
        # The runs go on while the next blob builds (each ELF is a copy of its own).
        for cpu in $(cpus_of "$name" "$variant"); do
            run_on_cpu "$name" "$variant" "$cpu" "$elf" &
            runs+=("$!")
        done
    done
    panic_never "$variant"
    wait "${runs[@]}"
}
mkdir -p "$OUT/elf"
pids=()
for variant in sp dp f32; do
    variant_pipeline "$variant" &
    pids+=("$!")
done
for pid in "${pids[@]}"; do
    wait "$pid" || { log "a firmware build failed"; exit 1; }
done

# The summary in a fixed order: the host's, then blob by blob, variant by variant, then the
# panic-never builds.
summary=("${host_summary[@]}")
for name in $BLOBS; do
    for variant in $(variants_of "$name"); do
        for cpu in $(cpus_of "$name" "$variant"); do
            mapfile -t -O "${#summary[@]}" summary <"$OUT/summary-$name-$variant-$cpu.txt"
            if [ -f "$OUT/stack-$name-$variant-$cpu.txt" ]; then cat "$OUT/stack-$name-$variant-$cpu.txt" >>"$OUT/stack.txt"; fi
        done
    done
done
for variant in sp dp f32; do
    mapfile -t -O "${#summary[@]}" summary <"$OUT/summary-panic-never-$variant.txt"
done
failures=$(printf '%s\n' "${summary[@]}" | grep -c '^FAIL' || true)

echo "== firmware check (host vs QEMU, bits; f32 builds against the host's f32 build) =="
printf '%s\n' "${summary[@]}"
if [ "$failures" -ne 0 ]; then
    echo "firmware check: $failures failed"
    exit 1
fi
echo "firmware check: passed (M4 and M7, software and hardware f64 and f32, RR (Heun × 5 and Euler × 2) and 6-joint blobs, 6-joint with physical effects, RR and 6-joint expansions (format 5), 10-joint chain, 6-joint with three tool points and its tool frame (format 6), 6-joint with the configuration-dependent task field (format 8))"
