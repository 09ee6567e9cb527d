#!/usr/bin/env python3
"""Lists the functions of a firmware ELF from which a panic is reachable, with the source lines
just before each call into core's panic machinery (a diagnostic for the panic-never build).

    python3 examples/firmware/find-panics.py path/to/cbd-firmware.elf

Needs llvm-nm and llvm-objdump (Debian: llvm). Build the ELF with the default features (the
panic-semihosting handler) and the same flags as the panic-never build.
"""
import bisect
import collections
import re
import subprocess
import sys


def main(elf):
    nm = subprocess.run(["llvm-nm", "-S", "--defined-only", "-C", elf], capture_output=True, text=True, check=True).stdout
    syms = []
    for line in nm.splitlines():
        p = line.split(None, 3)
        if len(p) == 4 and p[2] in "tT":
            syms.append((int(p[0], 16) & ~1, int(p[1], 16), p[3]))
    syms.sort()
    starts = [s[0] for s in syms]

    def owner(addr):
        i = bisect.bisect_right(starts, addr) - 1
        return syms[i][2] if i >= 0 and addr < syms[i][0] + syms[i][1] else "?"

    dis = subprocess.run(["llvm-objdump", "-d", "-l", "--no-show-raw-insn", "-C", elf], capture_output=True, text=True, check=True).stdout
    panicky = {s[2] for s in syms if re.search(r"panic|_fail\b|len_mismatch_fail|unwrap_failed|expect_failed", s[2])}
    calls = collections.defaultdict(set)
    sites = collections.Counter()
    recent = []
    for line in dis.splitlines():
        if line.startswith("; /") and "/rustc/" not in line:
            recent = (recent + [line[2:].strip()])[-2:]
            continue
        m = re.match(r"\s*([0-9a-f]+):\s+(bl|b|b\.w|blx)\s+0x([0-9a-f]+) <([^>]+)>", line)
        if not m:
            continue
        src, tgt = owner(int(m.group(1), 16)), owner(int(m.group(3), 16))
        calls[src].add(tgt)
        if tgt in panicky and src not in panicky:
            sites[(src.split("::h")[0], tgt.split("::h")[0], " / ".join(recent))] += 1
    reach = set(panicky)
    changed = True
    while changed:
        changed = False
        for f, cs in calls.items():
            if f not in reach and cs & reach:
                reach.add(f)
                changed = True
    callers = sorted(f.split("::h")[0] for f in reach - panicky)
    print("functions from which a panic is reachable:")
    for f in callers:
        print("   ", f)
    print("direct calls into the panic machinery (function, callee, last source lines):")
    for (f, tgt, where), count in sorted(sites.items()):
        print(f"   {count} × {f} -> {tgt}\n        at {where or '?'}")
    return 1 if callers else 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    sys.exit(main(sys.argv[1]))
