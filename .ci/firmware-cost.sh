#!/usr/bin/env bash
# Firmware cost (issue 5): instructions per evaluation under QEMU -icount shift=0, memory per model.
#
#   bash .ci/firmware-cost.sh            # prints a markdown table
#   bash .ci/firmware-cost.sh --write    # also replaces the "## Firmware (QEMU)" section of BENCHMARKS.md
#
# With -icount shift=0 SysTick advances one tick per 40 guest instructions (DESIGN.md §6): the
# counts below are ticks × 40, instructions to ±40, not cycles. Each row evaluates the 128 fixed
# configurations of examples/firmware/src/shared.rs; min/max are over those.
# Builds: "sp" = thumbv7em-none-eabihf defaults (single-precision FPU: f64 in software),
#         "dp" = -C target-cpu=cortex-m7 (the M7's double-precision FPU).
# The software-f64 build at N = 1024 needs ~9 min of QEMU: set CBD_FW_COST_FULL=1 to run it (on the M7
# only: the M4 runs the same ELF, and QEMU counts the same instructions, as the N = 64 and 256 rows show).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
FIRMWARE_LIB_ONLY=1 source "$ROOT/.ci/firmware.sh"
write=0
[ "${1:-}" = "--write" ] && write=1

fw_install
if command -v llvm-size >/dev/null 2>&1; then SIZE=llvm-size
elif command -v arm-none-eabi-size >/dev/null 2>&1; then SIZE=arm-none-eabi-size
else
    log "installing binutils-arm-none-eabi (for size)"
    sudo=""; [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq binutils-arm-none-eabi >/dev/null
    SIZE=arm-none-eabi-size
fi
fw_host_and_blobs

rows=()
for name in rr64 rr rr1024 six; do
    read -r n_points n_joints task_dim storage blob_bytes < <("$HOST" info "$OUT/blobs/$name.blob")
    for variant in dp sp; do
        runs="m7"
        [ "$variant" = sp ] && [ "$name" != rr1024 ] && runs="m7 m4"
        if [ "$variant" = sp ] && [ "$name" = rr1024 ] && [ "${CBD_FW_COST_FULL:-0}" != 1 ]; then
            log "skipping software-f64 N=1024 (CBD_FW_COST_FULL=1 runs it)"
            continue
        fi
        elf="$(fw_build "$name" "$variant")"
        read -r text _data bss < <($SIZE "$elf" | awk 'NR == 2 {print $1, $2, $3}')
        code=$((text - blob_bytes))
        for cpu in $runs; do
            run="$OUT/cost-$name-$variant-$cpu.txt"
            log "running $name $variant on $cpu"
            fw_run "$elf" "$cpu" "$run"
            read -r tmin tmax < <(awk '$1 ~ /^t[0-9]/ {v = $2 + 0; if (min == "" || v < min) min = v; if (v > max) max = v} END {print min, max}' "$run")
            load=$(awk '$1 == "load" {print $2}' "$run")
            ratio=$(awk -v a="$tmax" -v b="$tmin" 'BEGIN {printf "%.3f", a / b}')
            model="RR"
            [ "$n_joints" = 6 ] && model="6-joint"
            rows+=("| $model | $n_points | $cpu | $variant | $((tmin * 40)) | $((tmax * 40)) | $ratio | $((load * 40)) | $blob_bytes | $((storage * 8)) | $code |")
        done
    done
done

table="$(
    echo "RR arm (2 joints, m = 2) and a 6-joint UR5-like model (m = 3); Heun × 5 steps (10 stages); 128 configurations per row."
    echo "Instructions = SysTick ticks × 40 under \`qemu-system-arm -icount shift=0\` (±40; QEMU counts instructions, not cycles,"
    echo "so the same ELF gives the same counts on the M4 and the M7). RAM = \`storage_len\` × 8 bytes (the runtime's only RAM"
    echo "besides ~1 KiB of stack for a query). Code = ELF text − blob (whole firmware: runtime, decoder, libm, soft-float, printing)."
    echo "sp = thumbv7em-none-eabihf defaults (f64 in software); dp = \`-C target-cpu=cortex-m7\` (double-precision FPU, non-fused"
    echo "VMLA/VMLS only). Produced by \`bash .ci/firmware-cost.sh\`."
    echo
    echo "| model | N | CPU | build | instr/eval min | instr/eval max | max/min | instr to load | blob bytes | RAM bytes | code bytes |"
    echo "|---|---|---|---|---|---|---|---|---|---|---|"
    printf '%s\n' "${rows[@]}"
)"
echo "$table"

if [ "$write" = 1 ]; then
    bench="$ROOT/BENCHMARKS.md"
    [ -f "$bench" ] || printf '# Benchmarks\n' >"$bench"
    section="$(printf '## Firmware (QEMU)\n\n%s\n' "$table")"
    SECTION="$section" awk '
        BEGIN { s = ENVIRON["SECTION"]; done = 0; skip = 0 }
        /^## / { if (skip) skip = 0 }
        /^## Firmware \(QEMU\)[[:space:]]*$/ { print s; print ""; skip = 1; done = 1; next }
        !skip { print }
        END { if (!done) { print ""; print s } }
    ' "$bench" >"$bench.tmp"
    mv "$bench.tmp" "$bench"
    log "wrote the Firmware (QEMU) section of $bench"
fi
