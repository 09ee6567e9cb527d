/* check.c — host side of the C checks (.ci/c-ffi.sh):
 *
 *   check lines BLOB    # the firmware check's result lines (as `cbd-fw-host eval BLOB` prints them)
 *   check errors BLOB   # NULL pointers, short buffers, misaligned storage, corrupt blobs get their codes
 *   check size BLOB     # storage bytes the blob needs (the C firmware's static storage)
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cbd.h"
#include "shared.h"

static unsigned char *read_file(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) { perror(path); exit(1); }
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    rewind(f);
    unsigned char *data = malloc((size_t)size + 1);
    if (!data || fread(data, 1, (size_t)size, f) != (size_t)size) { perror(path); exit(1); }
    fclose(f);
    *len = (size_t)size;
    return data;
}

static int failures = 0;

static void expect(const char *what, CbdStatus got, CbdStatus want) {
    if (got != want) {
        fprintf(stderr, "FAIL %s: %s, expected %s\n", what, cbd_status_name((int32_t)got), cbd_status_name((int32_t)want));
        failures++;
    } else {
        printf("ok   %-44s %s\n", what, cbd_status_name((int32_t)got));
    }
}

static int errors(const unsigned char *blob, size_t len) {
    size_t bytes = 0;
    CbdCalibrator *cal = NULL;
    expect("storage size, NULL blob", cbd_storage_size(NULL, len, &bytes), CBD_ERR_NULL_POINTER);
    expect("storage size, NULL result", cbd_storage_size(blob, len, NULL), CBD_ERR_NULL_POINTER);
    expect("storage size", cbd_storage_size(blob, len, &bytes), CBD_OK);
    uint64_t *storage = malloc(bytes + 16); /* 8-byte aligned; +16 for the misaligned case */
    expect("load, NULL blob", cbd_load(NULL, len, storage, bytes, &cal), CBD_ERR_NULL_POINTER);
    expect("load, NULL storage", cbd_load(blob, len, NULL, bytes, &cal), CBD_ERR_NULL_POINTER);
    expect("load, NULL handle", cbd_load(blob, len, storage, bytes, NULL), CBD_ERR_NULL_POINTER);
    expect("load, storage one byte short", cbd_load(blob, len, storage, bytes - 1, &cal), CBD_ERR_STORAGE_TOO_SMALL);
    expect("load, no storage", cbd_load(blob, len, storage, 0, &cal), CBD_ERR_STORAGE_TOO_SMALL);
    expect("load, misaligned storage", cbd_load(blob, len, (unsigned char *)storage + 4, bytes, &cal), CBD_ERR_MISALIGNED);
    expect("load, blob one byte short", cbd_load(blob, len - 1, storage, bytes, &cal), CBD_ERR_TRUNCATED);
    unsigned char *corrupt = malloc(len);
    memcpy(corrupt, blob, len);
    corrupt[len / 2] ^= 0x10;
    expect("load, one bit flipped", cbd_load(corrupt, len, storage, bytes, &cal), CBD_ERR_CHECKSUM);
    if (cal != NULL) { fprintf(stderr, "FAIL a failed load left a handle\n"); failures++; }
    memcpy(corrupt, blob, len);
    corrupt[0] = 'X';
    expect("load, not a blob", cbd_load(corrupt, len, storage, bytes, &cal), CBD_ERR_BAD_MAGIC);
    expect("load", cbd_load(blob, len, storage, bytes, &cal), CBD_OK);
    size_t n = cbd_n_joints(cal), m = cbd_task_dim(cal);
    double q[CBD_MAX_JOINTS] = {0}, pos[CBD_MAX_TASK_DIM], jac[CBD_MAX_TASK_DIM * CBD_MAX_JOINTS], support;
    expect("evaluate, NULL handle", cbd_evaluate(NULL, q, n, pos, m, jac, m * n, NULL), CBD_ERR_NULL_POINTER);
    expect("evaluate, NULL q", cbd_evaluate(cal, NULL, n, pos, m, jac, m * n, NULL), CBD_ERR_NULL_POINTER);
    expect("evaluate, NULL position", cbd_evaluate(cal, q, n, NULL, m, jac, m * n, NULL), CBD_ERR_NULL_POINTER);
    expect("evaluate, NULL jacobian", cbd_evaluate(cal, q, n, pos, m, NULL, m * n, NULL), CBD_ERR_NULL_POINTER);
    expect("evaluate, wrong joint count", cbd_evaluate(cal, q, n + 1, pos, m, jac, m * n, NULL), CBD_ERR_QUERY_DIMENSION);
    expect("evaluate, short position buffer", cbd_evaluate(cal, q, n, pos, m - 1, jac, m * n, NULL), CBD_ERR_BUFFER_TOO_SMALL);
    expect("evaluate, short jacobian buffer", cbd_evaluate(cal, q, n, pos, m, jac, m * n - 1, NULL), CBD_ERR_BUFFER_TOO_SMALL);
    q[0] = 0.0 / 0.0;
    expect("evaluate, NaN joint", cbd_evaluate(cal, q, n, pos, m, jac, m * n, NULL), CBD_ERR_NON_FINITE_QUERY);
    q[0] = 0.0;
    expect("evaluate", cbd_evaluate(cal, q, n, pos, m, jac, m * n, &support), CBD_OK);
    expect("load over the handle's storage, corrupt", cbd_load(corrupt, len, storage, bytes, &cal), CBD_ERR_BAD_MAGIC);
    CbdCalibrator *stale = (CbdCalibrator *)storage;
    expect("evaluate, stale handle", cbd_evaluate(stale, q, n, pos, m, jac, m * n, NULL), CBD_ERR_BAD_HANDLE);
    printf("cbd-ffi %s, blob formats %u to %u\n", cbd_version(), cbd_oldest_format_version(), cbd_format_version());
    free(corrupt);
    free(storage);
    if (failures) fprintf(stderr, "%d error-path checks failed\n", failures);
    return failures ? 1 : 0;
}

static int lines(const unsigned char *blob, size_t len) {
    size_t bytes;
    CbdCalibrator *cal;
    CbdStatus s = cbd_storage_size(blob, len, &bytes);
    void *storage = s == CBD_OK ? malloc(bytes) : NULL;
    if (s == CBD_OK) s = cbd_load(blob, len, storage, bytes, &cal);
    if (s != CBD_OK) { fprintf(stderr, "load: %s\n", cbd_status_name((int32_t)s)); return 1; }
    size_t n = cbd_n_joints(cal), m = cbd_task_dim(cal);
    for (uint32_t i = 0; i < SHARED_COUNT; i++) {
        double q[CBD_MAX_JOINTS], pos[CBD_MAX_TASK_DIM], jac[CBD_MAX_TASK_DIM * CBD_MAX_JOINTS];
        char line[8 + 17 * (CBD_MAX_TASK_DIM + CBD_MAX_TASK_DIM * CBD_MAX_JOINTS)];
        shared_config(i, q, n);
        s = cbd_evaluate(cal, q, n, pos, m, jac, m * n, NULL);
        size_t k = s == CBD_OK ? shared_result(line, i, pos, m, jac, m * n) : shared_error(line, i);
        fwrite(line, 1, k, stdout);
    }
    free(storage);
    return 0;
}

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: check lines|errors|size BLOB\n");
        return 2;
    }
    size_t len;
    unsigned char *blob = read_file(argv[2], &len);
    int rc = 2;
    if (strcmp(argv[1], "lines") == 0) rc = lines(blob, len);
    else if (strcmp(argv[1], "errors") == 0) rc = errors(blob, len);
    else if (strcmp(argv[1], "size") == 0) {
        size_t bytes;
        CbdStatus s = cbd_storage_size(blob, len, &bytes);
        if (s == CBD_OK) printf("%zu\n", bytes);
        rc = s == CBD_OK ? 0 : 1;
    }
    free(blob);
    return rc;
}
