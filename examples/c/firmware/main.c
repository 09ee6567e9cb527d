/* main.c — the CbD runtime from C on a Cortex-M (QEMU mps2-an386 / mps2-an500), linked against
 * libcbd_ffi.a built for thumbv7em-none-eabihf. The C twin of examples/firmware: loads the embedded
 * blob into static storage, evaluates the SHARED_COUNT fixed configurations and prints every value's
 * bits through semihosting in the format of `cbd-fw-host eval` (lines `q…`), then `t… TICKS` per
 * evaluation and `load TICKS` (SysTick, 1 tick = 40 instructions under `qemu-system-arm -icount shift=0`).
 *
 * Build (.ci/c-ffi.sh does this):
 *   arm-none-eabi-gcc -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16 -O2 -ffp-contract=off \
 *     -ffunction-sections -fdata-sections -nostdlib -T link.ld -Wl,--gc-sections -I ffi/include -I examples/c \
 *     -DCBD_BLOB_PATH='"rr.blob"' -DCBD_STORAGE_BYTES=… main.c libcbd_ffi.a -lgcc -o fw.elf
 * No C library: startup, semihosting and printing are below. */
#include <stdint.h>

#include "cbd.h"
#include "shared.h"

#ifndef CBD_BLOB_PATH
#error "define CBD_BLOB_PATH (the blob to embed)"
#endif
#ifndef CBD_STORAGE_BYTES
#error "define CBD_STORAGE_BYTES (`check size BLOB` prints it)"
#endif

/* The model, in flash; the runtime reads its arrays in place. */
__asm__(".section .rodata.cbd_blob,\"a\",%progbits\n"
        ".balign 8\n"
        "cbd_blob:\n"
        ".incbin \"" CBD_BLOB_PATH "\"\n"
        "cbd_blob_end:\n"
        ".previous\n");
extern const unsigned char cbd_blob[], cbd_blob_end[];

/* All the RAM the runtime uses: the handle and the runtime's working memory. */
static _Alignas(CBD_STORAGE_ALIGN) unsigned char storage[CBD_STORAGE_BYTES];

/* ---- semihosting (ARM DUI 0471) */
static int semihost(int op, void *arg) {
    register int r0 __asm__("r0") = op;
    register void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}
static int console = -1;
static void out(const char *s, uint32_t len) {
    uint32_t args[3] = {(uint32_t)console, (uint32_t)s, len};
    semihost(0x05 /* SYS_WRITE */, args);
}
static void out_str(const char *s) {
    uint32_t len = 0;
    while (s[len]) len++;
    out(s, len);
}
static void __attribute__((noreturn)) finish(int ok) {
    semihost(0x18 /* SYS_EXIT */, (void *)(ok ? 0x20026 /* ApplicationExit */ : 0x20023 /* RunTimeErrorUnknown */));
    for (;;) {}
}

/* ---- SysTick: wrap-arounds counted (the counter has 24 bits) */
#define SYST_CSR (*(volatile uint32_t *)0xE000E010)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018)
#define RELOAD 0x00FFFFFFu
static volatile uint32_t wraps;
void systick_handler(void) { wraps++; }
static uint64_t ticks(void) {
    for (;;) {
        uint32_t w = wraps, c = SYST_CVR;
        if (wraps == w) return (uint64_t)w * (RELOAD + 1) + (RELOAD - c);
    }
}

static char *decimal(char *p, uint64_t v) {
    char tmp[20];
    int k = 0;
    do { tmp[k++] = (char)('0' + v % 10); v /= 10; } while (v);
    while (k) *p++ = tmp[--k];
    return p;
}

static int run(void) {
    char line[8 + 17 * (CBD_MAX_TASK_DIM + CBD_MAX_TASK_DIM * CBD_MAX_JOINTS)];
    CbdCalibrator *cal;
    uint64_t t0 = ticks();
    CbdStatus s = cbd_load(cbd_blob, (size_t)(cbd_blob_end - cbd_blob), storage, sizeof storage, &cal);
    uint64_t t1 = ticks();
    if (s != CBD_OK) {
        out_str("load error: ");
        out_str(cbd_status_name((int32_t)s));
        out_str("\n");
        return 0;
    }
    char *p = line;
    const char *load = "load ";
    while (*load) *p++ = *load++;
    p = decimal(p, t1 - t0);
    const char *unit = " ticks\n";
    while (*unit) *p++ = *unit++;
    out(line, (uint32_t)(p - line));
    size_t n = cbd_n_joints(cal), m = cbd_task_dim(cal);
    static uint32_t costs[SHARED_COUNT];
    for (uint32_t i = 0; i < SHARED_COUNT; i++) {
        double q[CBD_MAX_JOINTS], pos[CBD_MAX_TASK_DIM], jac[CBD_MAX_TASK_DIM * CBD_MAX_JOINTS];
        shared_config(i, q, n);
        uint64_t start = ticks();
        s = cbd_evaluate(cal, q, n, pos, CBD_MAX_TASK_DIM, jac, CBD_MAX_TASK_DIM * CBD_MAX_JOINTS, NULL);
        uint64_t end = ticks();
        costs[i] = (uint32_t)(end - start);
        size_t k = s == CBD_OK ? shared_result(line, i, pos, m, jac, m * n) : shared_error(line, i);
        out(line, (uint32_t)k);
    }
    for (uint32_t i = 0; i < SHARED_COUNT; i++) {
        p = shared_label(line, 't', i);
        *p++ = ' ';
        p = decimal(p, costs[i]);
        *p++ = '\n';
        out(line, (uint32_t)(p - line));
    }
    out_str("done\n");
    return 1;
}

/* ---- startup */
extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _stack_top;

void __attribute__((noreturn)) reset_handler(void) {
    for (uint32_t *src = &_sidata, *dst = &_sdata; dst < &_edata;) *dst++ = *src++;
    for (uint32_t *dst = &_sbss; dst < &_ebss;) *dst++ = 0;
    /* The FPU (CP10, CP11): the hard-float ABI passes doubles in its registers. */
    *(volatile uint32_t *)0xE000ED88 |= 0xFu << 20;
    __asm__ volatile("dsb\n isb" ::: "memory");
    SYST_RVR = RELOAD;
    SYST_CVR = 0;
    SYST_CSR = 7; /* processor clock, interrupt, enable */
    static const char tt[] = ":tt";
    uint32_t open_args[3] = {(uint32_t)tt, 4 /* "w" */, 3};
    console = semihost(0x01 /* SYS_OPEN */, open_args);
    finish(console >= 0 && run());
}

void fault_handler(void) { finish(0); }

__attribute__((section(".vectors"), used)) static void (*const vectors[16])(void) = {
    (void (*)(void))&_stack_top, reset_handler, fault_handler, fault_handler, fault_handler, fault_handler, fault_handler,
    0, 0, 0, 0, fault_handler, fault_handler, 0, fault_handler, systick_handler,
};
