/* shared.h — the fixed joint configurations and result lines of the firmware check
 * (examples/firmware/src/shared.rs, in C): the host check (check.c) and the C firmware
 * (firmware/main.c) print exactly what `cbd-fw-host eval BLOB` prints. Integer arithmetic and
 * exactly rounded IEEE operations only (compile with -ffp-contract=off): the same bits everywhere. */
#ifndef CBD_EXAMPLE_SHARED_H
#define CBD_EXAMPLE_SHARED_H

#include <stddef.h>
#include <stdint.h>

/* How many configurations are evaluated. */
#define SHARED_COUNT 128

/* Query configuration i: n joints, angles in [-pi, pi) (32-bit LCG, Numerical Recipes constants). */
static inline void shared_config(uint32_t i, double *out, size_t n) {
    uint32_t state = 0x2545F491u ^ (i * 0x9E3779B9u);
    for (size_t d = 0; d < n; d++) {
        state = state * 1664525u + 1013904223u;
        double unit = (double)(state >> 8) * (1.0 / 16777216.0);
        out[d] = 3.141592653589793 * (2.0 * unit - 1.0);
    }
}

/* Appends the 16 hex digits of a double's bits to p; returns the new end. */
static inline char *shared_hex(char *p, double v) {
    union { double d; uint64_t u; } bits = { v };
    for (int shift = 60; shift >= 0; shift -= 4) *p++ = "0123456789abcdef"[(bits.u >> shift) & 0xf];
    return p;
}

/* Appends "q<i>" with three digits. */
static inline char *shared_label(char *p, char c, uint32_t i) {
    *p++ = c;
    *p++ = (char)('0' + i / 100 % 10);
    *p++ = (char)('0' + i / 10 % 10);
    *p++ = (char)('0' + i % 10);
    return p;
}

/* One result line `q<i> <position…> | <jacobian, row-major…>\n` into line (room for
 * 8 + 17 * (m + m n) characters); returns its length. */
static inline size_t shared_result(char *line, uint32_t i, const double *position, size_t m, const double *jacobian, size_t mn) {
    char *p = shared_label(line, 'q', i);
    for (size_t a = 0; a < m; a++) { *p++ = ' '; p = shared_hex(p, position[a]); }
    *p++ = ' '; *p++ = '|';
    for (size_t k = 0; k < mn; k++) { *p++ = ' '; p = shared_hex(p, jacobian[k]); }
    *p++ = '\n';
    return (size_t)(p - line);
}

/* The line printed when evaluation i fails. */
static inline size_t shared_error(char *line, uint32_t i) {
    char *p = shared_label(line, 'q', i);
    const char *e = " error\n";
    while (*e) *p++ = *e++;
    return (size_t)(p - line);
}

#endif
