/* eval_csv.c — the CbD runtime from C on a host: load a blob file, evaluate every row of a
 * measurement CSV, print the calibrated position error as `cbd eval --json` computes it.
 *
 *   cc -O2 -std=c11 -ffp-contract=off -I ffi/include examples/c/eval_csv.c target/ffi/libcbd_ffi.a -lm -o eval_csv
 *   ./eval_csv arm.blob test.csv          # CSV: a header line, then joints…, measured position… per row
 *
 * Prints JSON: rows, extrapolating (kernel support < 0.05), calibrated {mean, median, p99, max},
 * every value in shortest round-trip form (%.17g), the same numbers as `cbd eval --json`.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cbd.h"

static int fail(const char *what, CbdStatus s) {
    fprintf(stderr, "eval_csv: %s: %s\n", what, cbd_status_name((int32_t)s));
    return 1;
}

static int compare(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* Linear interpolation between order statistics (as cbd's reports). */
static double quantile(const double *sorted, size_t count, double p) {
    double pos = p * (double)(count - 1);
    size_t lo = (size_t)floor(pos), hi = (size_t)ceil(pos);
    return sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - (double)lo);
}

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: eval_csv BLOB CSV\n");
        return 2;
    }
    /* The blob: read once, kept for the handle's lifetime (the model's arrays are read in place). */
    FILE *f = fopen(argv[1], "rb");
    if (!f) { perror(argv[1]); return 1; }
    fseek(f, 0, SEEK_END);
    long blob_len = ftell(f);
    rewind(f);
    unsigned char *blob = malloc(blob_len > 0 ? (size_t)blob_len : 1);
    if (!blob || fread(blob, 1, (size_t)blob_len, f) != (size_t)blob_len) { perror(argv[1]); return 1; }
    fclose(f);

    /* Storage: cbd_storage_size bytes, aligned to CBD_STORAGE_ALIGN (malloc's alignment suffices). */
    size_t bytes;
    CbdStatus s = cbd_storage_size(blob, (size_t)blob_len, &bytes);
    if (s != CBD_OK) return fail(argv[1], s);
    void *storage = malloc(bytes);
    CbdCalibrator *cal;
    s = cbd_load(blob, (size_t)blob_len, storage, bytes, &cal);
    if (s != CBD_OK) return fail(argv[1], s);
    size_t n = cbd_n_joints(cal), m = cbd_task_dim(cal);

    FILE *csv = fopen(argv[2], "r");
    if (!csv) { perror(argv[2]); return 1; }
    char line[4096];
    if (!fgets(line, sizeof line, csv)) { fprintf(stderr, "eval_csv: %s: empty\n", argv[2]); return 1; }
    size_t count = 0, capacity = 1024, far = 0;
    double *errors = malloc(capacity * sizeof *errors);
    while (fgets(line, sizeof line, csv)) {
        double row[CBD_MAX_JOINTS + CBD_MAX_TASK_DIM];
        char *p = line, *end;
        size_t k = 0;
        for (; k < n + m; k++) {
            row[k] = strtod(p, &end);
            if (end == p) break;
            p = end + (*end == ',');
        }
        if (k != n + m) { fprintf(stderr, "eval_csv: %s:%zu: expected %zu values\n", argv[2], count + 2, n + m); return 1; }
        double position[CBD_MAX_TASK_DIM], jacobian[CBD_MAX_TASK_DIM * CBD_MAX_JOINTS], support;
        s = cbd_evaluate(cal, row, n, position, CBD_MAX_TASK_DIM, jacobian, CBD_MAX_TASK_DIM * CBD_MAX_JOINTS, &support);
        if (s != CBD_OK) return fail(argv[2], s);
        if (support < 0.05) far++;
        double e2 = 0.0;
        for (size_t a = 0; a < m; a++) e2 += (position[a] - row[n + a]) * (position[a] - row[n + a]);
        if (count == capacity) errors = realloc(errors, (capacity *= 2) * sizeof *errors);
        errors[count++] = sqrt(e2);
    }
    fclose(csv);
    if (count == 0) { fprintf(stderr, "eval_csv: %s: no rows\n", argv[2]); return 1; }
    double sum = 0.0;
    for (size_t i = 0; i < count; i++) sum += errors[i];
    qsort(errors, count, sizeof *errors, compare);
    printf("{\"rows\": %zu, \"extrapolating\": %zu, \"calibrated\": {\"mean\": %.17g, \"median\": %.17g, \"p99\": %.17g, \"max\": %.17g}}\n",
           count, far, sum / (double)count, quantile(errors, count, 0.5), quantile(errors, count, 0.99), errors[count - 1]);
    free(errors);
    free(storage); /* nothing to release in the library: the handle lives in the storage */
    free(blob);
    return 0;
}
