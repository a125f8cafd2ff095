/* check_vectors: checks this evaluator against an artifact's test vectors.
 *
 *     optimis weights DOC --out W.json --vectors V.csv
 *     cc -std=c99 -O2 -Wall -Wextra -pedantic -I.. -o check check_vectors.c -lm
 *     ./check W.json V.csv
 *
 * Each row of V.csv (technique,x2_x,x2_y,x3_x,x3_y,x3l_x,x3l_y,weight) is a merge on a join path of
 * the model scene with the engine's weight; the error of ours is |ours - weight| relative to the
 * size of the terms, max(1, |weight|) * (1 + sum_h |beta_h|) (a stack's table and its beta_h w_h
 * may cancel). Exit status: 0 if every error is at most 1e-12 (and there is a row), 1 if not, 2 if
 * a file cannot be read. */
#define OPTIMIS_WEIGHTS_IMPLEMENTATION
#include "optimis_weights.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define HEADER "technique,x2_x,x2_y,x3_x,x3_y,x3l_x,x3l_y,weight"
#define TOLERANCE 1e-12

/* Cuts the line end (\n or \r\n) off `line`; returns its length, or -1 if the line did not fit. */
static long chomp(char *line, size_t size) {
    size_t len = strlen(line);
    if (len + 1 == size && line[len - 1] != '\n') return -1;
    while (len > 0 && (line[len - 1] == '\n' || line[len - 1] == '\r')) line[--len] = '\0';
    return (long)len;
}

/* The 8 fields of `line` (comma-separated numbers, the first 0, 1 or 2); 0 if malformed. */
static int parse_row(const char *line, double v[8]) {
    const char *p = line;
    char *end;
    int k;
    for (k = 0; k < 8; k++) {
        v[k] = strtod(p, &end);
        if (end == p || *end != (k < 7 ? ',' : '\0')) return 0;
        p = end + 1;
    }
    return v[0] == 0.0 || v[0] == 1.0 || v[0] == 2.0;
}

int main(int argc, char **argv) {
    optimis_weights w;
    char err[512], line[1024];
    double scale = 1.0, worst = 0.0, v[8];
    unsigned long rows = 0, over = 0, worst_row = 0, lineno = 1;
    FILE *csv;
    int h;
    if (argc != 3) {
        fprintf(stderr, "usage: %s ARTIFACT.json VECTORS.csv\n", argv[0]);
        return 2;
    }
    if (optimis_weights_load_file(argv[1], &w, err, sizeof err) != 0) {
        fprintf(stderr, "%s\n", err);
        return 2;
    }
    for (h = 0; h < w.n_heuristics; h++) scale += fabs(w.heuristics[h].beta);
    if (!(csv = fopen(argv[2], "r"))) {
        perror(argv[2]);
        optimis_weights_free(&w);
        return 2;
    }
    if (!fgets(line, sizeof line, csv) || chomp(line, sizeof line) < 0 || strcmp(line, HEADER) != 0) {
        fprintf(stderr, "%s: the header is not %s\n", argv[2], HEADER);
        goto bad;
    }
    while (fgets(line, sizeof line, csv)) {
        long len = chomp(line, sizeof line);
        double x2[2], x3[2], x3l[2], ours, error;
        optimis_path path;
        lineno++;
        if (len < 0) {
            fprintf(stderr, "%s:%lu: line too long\n", argv[2], lineno);
            goto bad;
        }
        if (len == 0) continue;
        if (!parse_row(line, v)) {
            fprintf(stderr, "%s:%lu: not a row of %s\n", argv[2], lineno, HEADER);
            goto bad;
        }
        x2[0] = v[1]; x2[1] = v[2]; x3[0] = v[3]; x3[1] = v[4]; x3l[0] = v[5]; x3l[1] = v[6];
        optimis_model_path(&w, x2, x3, x3l, &path);
        ours = optimis_weights_eval(&w, (int)v[0], &path);
        error = fabs(ours - v[7]) / (fmax(1.0, fabs(v[7])) * scale);
        rows++;
        if (!(error <= TOLERANCE)) over++;
        if (!isnan(worst) && !(error <= worst)) { worst = error; worst_row = lineno; } /* a NaN sticks */
    }
    if (ferror(csv)) {
        fprintf(stderr, "%s: read error\n", argv[2]);
        goto bad;
    }
    fclose(csv);
    printf("%s (%s, %s): %lu rows, worst error %.3e", argv[1], w.strategy,
           w.kind == OPTIMIS_KIND_TABLE ? "table" : w.kind == OPTIMIS_KIND_STACK ? "stack" : "heuristic", rows, worst);
    if (worst_row) printf(" (line %lu)", worst_row);
    printf(", %lu above %.0e\n", over, TOLERANCE);
    optimis_weights_free(&w);
    return rows > 0 && over == 0 ? 0 : 1;
bad:
    fclose(csv);
    optimis_weights_free(&w);
    return 2;
}
