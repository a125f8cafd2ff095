/* optimis_weights.h: evaluate an optimis weights artifact (JSON, format "optimis-weights",
 * version 1) in C99. Single file, stb style: declarations always; in exactly one .c file write
 *
 *     #define OPTIMIS_WEIGHTS_IMPLEMENTATION
 *     #include "optimis_weights.h"
 *
 * for the definitions (define OPTIMIS_WEIGHTS_DEF as `static` first to keep them private; the
 * compiler then warns of those the file does not call). It needs the C standard library only: link
 * with -lm. It follows the Rust reference evaluator (src/sim/weights/function.rs, densities.rs)
 * operation for operation, so weights agree to a few units in the last place; compile without
 * -ffast-math.
 *
 * The artifact (`optimis weights DOC --out W.json`) is a run's weight function. The weight of a
 * merge by technique m (0: at plane 1, the pixel; 1: at plane 2; 2: at plane 3) on a join path is
 *
 *     w_m = T_m(cell(r2, r3, phi)) + sum_h beta_h * w_h,m(path)
 *
 * with T the table on cells (0 when the artifact has none: kind "heuristic") and w_h each per-path
 * heuristic (balance, power, correlation-aware, switch, one technique; docs/model.md section 9).
 *
 * Frame and units (docs/model.md section 1). Three planes orthogonal to z: plane 1 at z = 0 holds
 * the pixel at the origin, plane 2 is at z = L2, plane 3 at z = L2 + L3; the light starts on plane
 * 3. A point on a plane is 2-D, (x, y), in the plane's own coordinates, whose origin is where the
 * z axis through the pixel crosses it. Lengths are in the scene's unit (the unit of L2, L3, R and the
 * cell edges, which the artifact's "scene" states), angles in radians, densities per unit area of
 * that unit. The join path of a merge is (x1 = 0, x2, x3): for a merge at plane 3, x3 is the
 * camera's vertex x3c and the light path started at x3l, within R of it; for merges at planes 1
 * and 2, x3 = x3l is the light path's start.
 *
 * A renderer of the model scene calls optimis_model_path() for its inputs. A renderer of another
 * scene fills an optimis_path itself (docs/model.md section 9): for a join path of three vertices
 * x1 (where its camera sub-path starts; the pixel here), x2 and x3, the densities per unit area with
 * which its camera sub-path generates x2 (from x1) and then x3, and its light sub-path its start
 * x3l, then x2 (from x3) and then x1. The heuristics read only these, and r3 for the switch. The
 * table's cells (r2, r3, phi) and the switch's radius are the model scene's geometry: a table or a
 * stack fitted there does not transfer to another scene, a heuristic does. The correlation-aware
 * formula's area (pi R^2), N_F and N_B are the run's; a renderer merging with another radius or
 * other path counts sets its own in the loaded heuristics[h].
 */
#ifndef OPTIMIS_WEIGHTS_H
#define OPTIMIS_WEIGHTS_H

#include <stddef.h>

#ifndef OPTIMIS_WEIGHTS_DEF
#define OPTIMIS_WEIGHTS_DEF extern
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* The reader's bounds: it refuses an artifact beyond them. */
#define OPTIMIS_WEIGHTS_MAX_CELLS 256      /* table cells */
#define OPTIMIS_WEIGHTS_MAX_HEURISTICS 16  /* stacked heuristics */
#define OPTIMIS_WEIGHTS_MAX_RINGS 64       /* illumination rings */
#define OPTIMIS_WEIGHTS_MAX_EDGES 4096     /* r2 and r3 cell edges together */
#define OPTIMIS_WEIGHTS_MAX_DEPTH 32       /* JSON nesting */
#define OPTIMIS_WEIGHTS_MAX_BYTES (4L << 20) /* the largest file load_file reads */
#define OPTIMIS_WEIGHTS_MAX_NAME 128       /* strings kept (strategy, names), with their NUL */

typedef enum { OPTIMIS_KIND_TABLE, OPTIMIS_KIND_HEURISTIC, OPTIMIS_KIND_STACK } optimis_kind;

typedef enum {
    OPTIMIS_ONE_TECHNIQUE,    /* weight 1 on `technique` */
    OPTIMIS_SWITCH,           /* technique 1 if r3 <= radius, else 2 */
    OPTIMIS_BALANCE,          /* p_m / sum_k p_k */
    OPTIMIS_POWER,            /* p_m^e / sum_k p_k^e */
    OPTIMIS_CORRELATION_AWARE /* n_m p_m / sum_k n_k p_k, effective counts n from area, N_F, N_B */
} optimis_formula;

/* One ring of the light's radial profile on plane 3: inner <= |x| < outer has level `level`. */
typedef struct { double inner, outer, level; } optimis_ring;

/* One per-path heuristic and its coefficient beta. */
typedef struct {
    char name[OPTIMIS_WEIGHTS_MAX_NAME]; /* e.g. "correlation_aware_planes23" */
    double beta;
    optimis_formula formula;
    int technique;                      /* OPTIMIS_ONE_TECHNIQUE: 0, 1 or 2 */
    double radius;                      /* OPTIMIS_SWITCH: its radius a on plane 3 */
    double exponent;                    /* OPTIMIS_POWER: e */
    double area, light_paths, camera_paths; /* OPTIMIS_CORRELATION_AWARE: pi R^2, N_F, N_B */
    int techniques[3];                  /* the techniques it weighs (others get 0) */
} optimis_heuristic;

/* The model scene the artifact refers to (docs/model.md sections 1-4). */
typedef struct {
    double l2, l3;           /* plane 1 to plane 2, plane 2 to plane 3 */
    double beta_rad;         /* the plane-2 lobe's width */
    double merge_radius;     /* R */
    double light_paths;      /* N_F */
    double camera_paths;     /* N_B */
    double flux;             /* sum of level x ring area: the start density is level / flux */
    int n_rings;
    optimis_ring rings[OPTIMIS_WEIGHTS_MAX_RINGS];
} optimis_scene;

/* A loaded artifact. Read its fields freely; release it with optimis_weights_free(). */
typedef struct {
    char strategy[OPTIMIS_WEIGHTS_MAX_NAME]; /* the noise-table row, e.g. "optimal_stacked" */
    char fingerprint[OPTIMIS_WEIGHTS_MAX_NAME]; /* provenance.fingerprint of the run */
    int recommended;                         /* whether the run recommended this row */
    optimis_kind kind;
    optimis_scene scene;
    /* The table (NULL for kind heuristic): cell (i2, i3, iphi) at index (i2*n_r3 + i3)*phi_bins
     * + iphi holds (T0, T1, T2). Bin k of an axis is [edges[k], edges[k+1]), the last to infinity. */
    size_t n_r2, n_r3;
    unsigned phi_bins;                        /* equal bins of phi over [0, pi] */
    double *r2_edges, *r3_edges;
    double (*table)[3];
    int n_heuristics;
    optimis_heuristic heuristics[OPTIMIS_WEIGHTS_MAX_HEURISTICS];
} optimis_weights;

/* A join path (0, x2, x3) as the evaluator reads it at a merge. */
typedef struct {
    double r2;          /* |x2|, the plane-2 vertex's distance from the axis */
    double r3;          /* |x3| (the camera's x3c for a merge at plane 3) */
    double phi;         /* the angle between the vectors x2 and x3, in [0, pi] */
    double camera_x2;   /* p_c(x2): the camera sub-path's density of x2 */
    double camera_x3;   /* p_c(x3 | x2): then of x3 */
    double light_start; /* p_l(x3l) = I(x3l) / flux: the light sub-path's density of its start */
    double light_x2;    /* p_l(x2 | x3): then of x2 */
    double light_x1;    /* p_l(x1 | x2, x3): then of the pixel x1 */
} optimis_path;

/* Reads the artifact at `path` (at most OPTIMIS_WEIGHTS_MAX_BYTES) into *out and checks it as the
 * Rust reader does: format and version, required fields and their types, a complete table on
 * valid axes, bounded sizes. Returns 0 on success; otherwise nonzero, with a message in err (if
 * err is not NULL, truncated to errlen bytes) and *out left empty (freeing it is harmless). */
OPTIMIS_WEIGHTS_DEF int optimis_weights_load_file(const char *path, optimis_weights *out, char *err, size_t errlen);

/* The same from the NUL-terminated JSON text `json`. */
OPTIMIS_WEIGHTS_DEF int optimis_weights_load_string(const char *json, optimis_weights *out, char *err, size_t errlen);

/* Releases what a load allocated and empties *w (NULL and empty artifacts are fine). */
OPTIMIS_WEIGHTS_DEF void optimis_weights_free(optimis_weights *w);

/* The weight of a merge by `technique` (0: plane 1, the pixel; 1: plane 2; 2: plane 3) on the join
 * path `path`: the table's weight in the cell of (r2, r3, phi) plus sum_h beta_h * w_h. A fitted
 * table's weights may be negative or exceed 1; the three techniques' weights of one path sum to 1.
 * Returns NaN for a technique outside 0..2. Thread-safe: it only reads *w and *path. */
OPTIMIS_WEIGHTS_DEF double optimis_weights_eval(const optimis_weights *w, int technique, const optimis_path *path);

/* The evaluator's inputs for the model scene's join path through x2 on plane 2 and x3 on plane 3
 * whose light path started at x3l on plane 3 (x3l = x3 for merges at planes 1 and 2), from the
 * artifact's scene: r2, r3, phi and the vertex densities per unit area, with d1 = |(x2, L2)|,
 * d2 = |(x3 - x2, L3)|, theta the deflection at x2 and q(theta) the lobe's solid-angle pdf:
 * camera_x2 = L2^2/(pi d1^4), camera_x3 = q L3/d2^3, light_x2 = L3^2/(pi d2^4),
 * light_x1 = q L2/d1^3, light_start = level/flux of the ring holding |x3l| (0 outside them). */
OPTIMIS_WEIGHTS_DEF void optimis_model_path(const optimis_weights *w, const double x2[2], const double x3[2],
                                            const double x3l[2], optimis_path *out);

#ifdef __cplusplus
}
#endif
#endif /* OPTIMIS_WEIGHTS_H */

#ifdef OPTIMIS_WEIGHTS_IMPLEMENTATION
#ifndef OPTIMIS_WEIGHTS_IMPLEMENTED
#define OPTIMIS_WEIGHTS_IMPLEMENTED

#include <errno.h>
#include <locale.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define OW_PI 3.14159265358979323846

/* ---- A bounded JSON reader. The text is first checked whole (syntax, depth); values are then
 * found by key. Every function returns the index just past what it read, or 0 on an error (a value
 * never ends at 0), with the message in the document's err. */
typedef struct { const char *s; size_t n; char *err; size_t errlen; } ow_doc;

/* Sets the error message (printf-style); returns 0, the functions' error. */
static size_t ow_fail(ow_doc *d, const char *fmt, ...) {
    va_list ap;
    if (d->err && d->errlen > 0) {
        va_start(ap, fmt);
        vsnprintf(d->err, d->errlen, fmt, ap);
        va_end(ap);
    }
    return 0;
}

/* The index of the first non-whitespace character from i. */
static size_t ow_ws(const ow_doc *d, size_t i) {
    while (i < d->n && (d->s[i] == ' ' || d->s[i] == '\t' || d->s[i] == '\n' || d->s[i] == '\r')) i++;
    return i;
}

/* Whether the character at i is a digit. */
static int ow_digit(const ow_doc *d, size_t i) { return i < d->n && d->s[i] >= '0' && d->s[i] <= '9'; }

/* The 4 hex digits at i (a \u escape's) into *out; 0 if they are not. */
static int ow_hex4(const ow_doc *d, size_t i, unsigned *out) {
    size_t k;
    if (i + 4 > d->n) return 0;
    for (*out = 0, k = 0; k < 4; k++) {
        char c = d->s[i + k];
        int h = c >= '0' && c <= '9'   ? c - '0'
                : c >= 'a' && c <= 'f' ? c - 'a' + 10
                : c >= 'A' && c <= 'F' ? c - 'A' + 10 : -1;
        if (h < 0) return 0;
        *out = *out * 16 + (unsigned)h;
    }
    return 1;
}

/* The string at i, decoded (UTF-8) into out[cap] when out is not NULL: at most cap - 1 bytes and a
 * NUL; *len gets its whole decoded length. */
static size_t ow_string(ow_doc *d, size_t i, char *out, size_t cap, size_t *len) {
    size_t k = 0, b, nb;
    if (i >= d->n || d->s[i] != '"') return ow_fail(d, "expected a string at byte %lu", (unsigned long)i);
    for (i++;;) {
        unsigned long c;
        unsigned char bytes[4];
        int raw = 1; /* a byte as it stands (raw UTF-8 passes through unchanged) */
        if (i >= d->n) return ow_fail(d, "unterminated string");
        c = (unsigned char)d->s[i++];
        if (c == '"') break;
        if (c < 0x20) return ow_fail(d, "control character in a string at byte %lu", (unsigned long)i - 1);
        if (c == '\\') {
            unsigned u, lo;
            char e = i < d->n ? d->s[i++] : 0;
            switch (e) {
            case '"': case '\\': case '/': c = (unsigned char)e; break;
            case 'b': c = '\b'; break;
            case 'f': c = '\f'; break;
            case 'n': c = '\n'; break;
            case 'r': c = '\r'; break;
            case 't': c = '\t'; break;
            case 'u':
                if (!ow_hex4(d, i, &u)) return ow_fail(d, "bad \\u escape at byte %lu", (unsigned long)i);
                i += 4;
                raw = 0;
                if (u >= 0xDC00 && u <= 0xDFFF) return ow_fail(d, "lone surrogate at byte %lu", (unsigned long)i);
                if (u >= 0xD800 && u <= 0xDBFF) {
                    if (i + 2 > d->n || d->s[i] != '\\' || d->s[i + 1] != 'u' || !ow_hex4(d, i + 2, &lo)
                        || lo < 0xDC00 || lo > 0xDFFF)
                        return ow_fail(d, "lone surrogate at byte %lu", (unsigned long)i);
                    i += 6;
                    c = 0x10000UL + ((unsigned long)(u - 0xD800) << 10) + (lo - 0xDC00);
                } else {
                    c = u;
                }
                break;
            default: return ow_fail(d, "bad escape at byte %lu", (unsigned long)i - 1);
            }
        }
        /* A \u escape's code point in UTF-8: continuation bytes last to first, then the lead. */
        nb = raw || c < 0x80 ? 1 : c < 0x800 ? 2 : c < 0x10000 ? 3 : 4;
        for (b = nb - 1; b > 0; b--, c >>= 6) bytes[b] = (unsigned char)(0x80 | (c & 0x3F));
        bytes[0] = (unsigned char)(nb == 1 ? c : ((0xF00UL >> nb) & 0xFF) | c);
        for (b = 0; b < nb; b++, k++)
            if (out && k + 1 < cap) out[k] = (char)bytes[b];
    }
    if (out && cap > 0) out[k < cap ? k : cap - 1] = '\0';
    if (len) *len = k;
    return i;
}

/* The number at i (JSON's grammar, then strtod in the "C" sense whatever the locale). */
static size_t ow_number(ow_doc *d, size_t i, double *out) {
    char buf[256], *end, point = localeconv()->decimal_point[0];
    size_t j = i, k;
    double v;
    if (j < d->n && d->s[j] == '-') j++;
    if (j < d->n && d->s[j] == '0') j++;
    else if (ow_digit(d, j)) while (ow_digit(d, j)) j++;
    else return ow_fail(d, "invalid value at byte %lu", (unsigned long)i);
    if (j < d->n && d->s[j] == '.') {
        if (!ow_digit(d, ++j)) return ow_fail(d, "invalid number at byte %lu", (unsigned long)i);
        while (ow_digit(d, j)) j++;
    }
    if (j < d->n && (d->s[j] == 'e' || d->s[j] == 'E')) {
        j++;
        if (j < d->n && (d->s[j] == '+' || d->s[j] == '-')) j++;
        if (!ow_digit(d, j)) return ow_fail(d, "invalid number at byte %lu", (unsigned long)i);
        while (ow_digit(d, j)) j++;
    }
    if (j - i >= sizeof buf) return ow_fail(d, "number too long at byte %lu", (unsigned long)i);
    for (k = 0; k < j - i; k++) buf[k] = d->s[i + k] == '.' ? point : d->s[i + k];
    buf[k] = '\0';
    v = strtod(buf, &end);
    if (end != buf + k || !isfinite(v)) return ow_fail(d, "number out of range at byte %lu", (unsigned long)i);
    if (out) *out = v;
    return j;
}

/* Checks (and skips) the value at i, nested `depth` containers deep. */
static size_t ow_value(ow_doc *d, size_t i, int depth) {
    static const char *const words[3] = {"true", "false", "null"};
    int w;
    i = ow_ws(d, i);
    if (i >= d->n) return ow_fail(d, "unexpected end of the JSON text");
    if (d->s[i] == '{' || d->s[i] == '[') {
        char close = d->s[i] == '{' ? '}' : ']';
        if (depth >= OPTIMIS_WEIGHTS_MAX_DEPTH)
            return ow_fail(d, "JSON nested deeper than %d", OPTIMIS_WEIGHTS_MAX_DEPTH);
        i = ow_ws(d, i + 1);
        if (i < d->n && d->s[i] == close) return i + 1;
        for (;;) {
            if (close == '}') {
                if (!(i = ow_string(d, ow_ws(d, i), NULL, 0, NULL))) return 0;
                i = ow_ws(d, i);
                if (i >= d->n || d->s[i] != ':') return ow_fail(d, "expected ':' at byte %lu", (unsigned long)i);
                i++;
            }
            if (!(i = ow_value(d, i, depth + 1))) return 0;
            i = ow_ws(d, i);
            if (i < d->n && d->s[i] == ',') { i = ow_ws(d, i + 1); continue; }
            if (i < d->n && d->s[i] == close) return i + 1;
            return ow_fail(d, "expected ',' or '%c' at byte %lu", close, (unsigned long)i);
        }
    }
    if (d->s[i] == '"') return ow_string(d, i, NULL, 0, NULL);
    for (w = 0; w < 3; w++) {
        size_t len = strlen(words[w]);
        if (d->n - i >= len && memcmp(d->s + i, words[w], len) == 0) return i + len;
    }
    return ow_number(d, i, NULL);
}

/* ---- Navigating the checked document. These return 0, or -1 with a message naming the field
 * (`where` is the object's name in messages). */
#define OW_ERR(...) ((void)ow_fail(d, __VA_ARGS__), -1)

/* Finds `key` in the object at obj: *at is its value's index, or 0 if absent. */
static int ow_key(ow_doc *d, size_t obj, const char *where, const char *key, size_t *at) {
    size_t i = ow_ws(d, obj + 1), len;
    char name[64];
    *at = 0;
    while (d->s[i] == '"') {
        i = ow_ws(d, ow_ws(d, ow_string(d, i, name, sizeof name, &len)) + 1); /* past the ':' */
        if (len == strlen(key) && len < sizeof name && memcmp(name, key, len) == 0) {
            if (*at) return OW_ERR("%s: duplicate field \"%s\"", where, key);
            *at = i;
        }
        i = ow_ws(d, ow_value(d, i, 0));
        if (d->s[i] == ',') i = ow_ws(d, i + 1);
    }
    return 0;
}

/* Whether the value at `at` is of `type` ('{', '[', '"', 'b' for a boolean, '0' for a number). */
static int ow_type(ow_doc *d, size_t at, char type, const char *where, const char *key) {
    static const char types[] = "{[\"b0";
    static const char *const names[] = {"an object", "an array", "a string", "a boolean", "a number"};
    char c = d->s[at], t = c == 't' || c == 'f' ? 'b' : c == '-' || (c >= '0' && c <= '9') ? '0' : c;
    if (t == type) return 0;
    return OW_ERR("%s%s%s: expected %s", where, key ? "." : "", key ? key : "", names[strchr(types, type) - types]);
}

/* The required field `key` of obj, of `type`, at *at. */
static int ow_need(ow_doc *d, size_t obj, const char *where, const char *key, char type, size_t *at) {
    if (ow_key(d, obj, where, key, at)) return -1;
    if (!*at) return OW_ERR("%s: missing field \"%s\"", where, key);
    return ow_type(d, *at, type, where, key);
}

/* The required number `key` of obj. */
static int ow_num(ow_doc *d, size_t obj, const char *where, const char *key, double *out) {
    size_t at;
    if (ow_need(d, obj, where, key, '0', &at)) return -1;
    ow_number(d, at, out);
    return 0;
}

/* The required whole number `key` of obj, in [0, max]. */
static int ow_count(ow_doc *d, size_t obj, const char *where, const char *key, double max, size_t *out) {
    double v;
    if (ow_num(d, obj, where, key, &v)) return -1;
    if (!(v >= 0 && v <= max && v == floor(v)))
        return OW_ERR("%s.%s: expected a whole number in [0, %g]", where, key, max);
    *out = (size_t)v;
    return 0;
}

/* The required string `key` of obj into out[cap] (longer, or holding a NUL: an error). */
static int ow_str(ow_doc *d, size_t obj, const char *where, const char *key, char *out, size_t cap) {
    size_t at, len;
    if (ow_need(d, obj, where, key, '"', &at)) return -1;
    ow_string(d, at, out, cap, &len);
    if (len >= cap || strlen(out) != len) return OW_ERR("%s.%s: too long or holds a NUL", where, key);
    return 0;
}

/* The boolean at `at`. */
static int ow_bool(ow_doc *d, size_t at, const char *where, const char *key, int *out) {
    if (ow_type(d, at, 'b', where, key)) return -1;
    *out = d->s[at] == 't';
    return 0;
}

/* The array `key` of obj: its elements' indices into at[max] (more: an error), their number in *n.
 * Absent, it is empty if `optional`. */
static int ow_array(ow_doc *d, size_t obj, const char *where, const char *key, int optional, size_t *at, size_t max,
                    size_t *n) {
    size_t a = 0, i;
    *n = 0;
    if (optional && ow_key(d, obj, where, key, &a)) return -1;
    if (optional && !a) return 0;
    if (ow_need(d, obj, where, key, '[', &a)) return -1;
    for (i = ow_ws(d, a + 1); d->s[i] != ']'; i = ow_ws(d, i + 1)) {
        if (*n == max) return OW_ERR("%s.%s: more than %lu elements", where, key, (unsigned long)max);
        at[(*n)++] = i;
        i = ow_ws(d, ow_value(d, i, 0));
        if (d->s[i] == ']') break;
    }
    return 0;
}

/* ---- The artifact. */

/* The edges `key` of the cells (into a new array *out of *n, at most `room`): from 0, increasing. */
static int ow_edges(ow_doc *d, size_t cells, const char *key, double **out, size_t *n, size_t *at, size_t room) {
    size_t k;
    if (ow_array(d, cells, "cells", key, 0, at, room, n)) return -1;
    if (!(*out = (double *)malloc((*n ? *n : 1) * sizeof **out))) return OW_ERR("out of memory");
    for (k = 0; k < *n; k++) {
        if (ow_type(d, at[k], '0', "cells", key)) return -1;
        ow_number(d, at[k], *out + k);
        if (k == 0 ? (*out)[0] != 0.0 : !((*out)[k] > (*out)[k - 1])) break;
    }
    if (*n == 0 || k < *n) return OW_ERR("cells.%s: edges must start at 0 and increase", key);
    return 0;
}

/* One heuristic, the object at obj. */
static int ow_heuristic(ow_doc *d, size_t obj, const char *where, optimis_heuristic *h) {
    static const char *const kinds[5] = {"one_technique", "switch", "balance", "power", "correlation_aware"};
    char kind[32], fwhere[64];
    size_t f, at[4], n = 0, k;
    if (ow_type(d, obj, '{', where, NULL) || ow_str(d, obj, where, "name", h->name, sizeof h->name)
        || ow_num(d, obj, where, "beta", &h->beta) || ow_need(d, obj, where, "formula", '{', &f))
        return -1;
    snprintf(fwhere, sizeof fwhere, "%s.formula", where);
    if (ow_str(d, f, fwhere, "kind", kind, sizeof kind)) return -1;
    for (k = 0; k < 5 && strcmp(kind, kinds[k]) != 0; k++) {}
    if (k == 5) return OW_ERR("%s: unknown kind \"%s\"", fwhere, kind);
    h->formula = (optimis_formula)k;
    if ((k == 0 && ow_count(d, f, fwhere, "technique", 2, &n)) || (k == 1 && ow_num(d, f, fwhere, "radius", &h->radius))
        || (k == 3 && ow_num(d, f, fwhere, "exponent", &h->exponent))
        || (k == 4 && (ow_num(d, f, fwhere, "area", &h->area) || ow_num(d, f, fwhere, "light_paths", &h->light_paths)
                       || ow_num(d, f, fwhere, "camera_paths", &h->camera_paths))))
        return -1;
    h->technique = (int)n;
    if (ow_array(d, obj, where, "techniques", 0, at, 4, &n)) return -1;
    if (n != 3) return OW_ERR("%s.techniques: expected 3 booleans", where);
    for (k = 0; k < 3; k++)
        if (ow_bool(d, at[k], where, "techniques", &h->techniques[k])) return -1;
    return 0;
}

/* The table: every cell of the axes exactly once, into w->table by cell index. */
static int ow_table(ow_doc *d, size_t root, optimis_weights *w, size_t ncells, size_t *el) {
    unsigned char seen[OPTIMIS_WEIGHTS_MAX_CELLS] = {0};
    char where[32];
    size_t count, k, m, c[3], wat[4], nw, cell;
    if (ow_array(d, root, "artifact", "table", 1, el, OPTIMIS_WEIGHTS_MAX_CELLS, &count)) return -1;
    if (!ncells) return count ? OW_ERR("a table without cells") : 0;
    if (count != ncells)
        return OW_ERR("the table has %lu cells, its axes %lu", (unsigned long)count, (unsigned long)ncells);
    if (!(w->table = (double (*)[3])malloc(ncells * sizeof *w->table))) return OW_ERR("out of memory");
    for (k = 0; k < count; k++) {
        snprintf(where, sizeof where, "table[%lu]", (unsigned long)k);
        if (ow_type(d, el[k], '{', where, NULL) || ow_count(d, el[k], where, "r2", (double)(w->n_r2 - 1), &c[0])
            || ow_count(d, el[k], where, "r3", (double)(w->n_r3 - 1), &c[1])
            || ow_count(d, el[k], where, "phi", (double)(w->phi_bins - 1), &c[2])
            || ow_array(d, el[k], where, "w", 0, wat, 4, &nw))
            return -1;
        if (nw != 3) return OW_ERR("%s.w: expected 3 numbers", where);
        cell = (c[0] * w->n_r3 + c[1]) * w->phi_bins + c[2];
        if (seen[cell]++) return OW_ERR("%s: cell (%lu, %lu, %lu) is listed twice", where, (unsigned long)c[0],
                                        (unsigned long)c[1], (unsigned long)c[2]);
        for (m = 0; m < 3; m++) {
            if (ow_type(d, wat[m], '0', where, "w")) return -1;
            ow_number(d, wat[m], &w->table[cell][m]);
        }
    }
    return 0;
}

/* The checked document's artifact, the object at root, into *w (el: room for MAX_EDGES indices). */
static int ow_artifact(ow_doc *d, size_t root, optimis_weights *w, size_t *el) {
    static const char *const kinds[3] = {"table", "heuristic", "stack"};
    static const char *const scene_fields[7] = {"l2", "l3", "beta_rad", "merge_radius", "light_paths", "camera_paths",
                                                "flux"};
    double *scene_values[7];
    double version;
    size_t at, scene, cells, count, k, ncells = 0, phi_bins;
    char text[OPTIMIS_WEIGHTS_MAX_NAME], where[32];
    if (ow_type(d, root, '{', "the artifact", NULL) || ow_str(d, root, "artifact", "format", text, sizeof text)
        || ow_num(d, root, "artifact", "version", &version))
        return -1;
    if (strcmp(text, "optimis-weights") != 0 || version != 1.0)
        return OW_ERR("format \"%s\" version %g, expected \"optimis-weights\" version 1", text, version);
    if (ow_str(d, root, "artifact", "strategy", w->strategy, sizeof w->strategy)
        || ow_need(d, root, "artifact", "recommended", 'b', &at) || ow_str(d, root, "artifact", "kind", text, sizeof text))
        return -1;
    w->recommended = d->s[at] == 't';
    for (k = 0; k < 3 && strcmp(text, kinds[k]) != 0; k++) {}
    if (k == 3) return OW_ERR("artifact.kind: \"%s\" is not table, heuristic or stack", text);
    w->kind = (optimis_kind)k;
    /* The scene. */
    scene_values[0] = &w->scene.l2; scene_values[1] = &w->scene.l3; scene_values[2] = &w->scene.beta_rad;
    scene_values[3] = &w->scene.merge_radius; scene_values[4] = &w->scene.light_paths;
    scene_values[5] = &w->scene.camera_paths; scene_values[6] = &w->scene.flux;
    if (ow_need(d, root, "artifact", "scene", '{', &scene)) return -1;
    for (k = 0; k < 7; k++)
        if (ow_num(d, scene, "scene", scene_fields[k], scene_values[k])) return -1;
    if (ow_array(d, scene, "scene", "rings", 0, el, OPTIMIS_WEIGHTS_MAX_RINGS, &count)) return -1;
    for (w->scene.n_rings = (int)count, k = 0; k < count; k++) {
        optimis_ring *r = &w->scene.rings[k];
        snprintf(where, sizeof where, "scene.rings[%lu]", (unsigned long)k);
        if (ow_type(d, el[k], '{', where, NULL) || ow_num(d, el[k], where, "inner", &r->inner)
            || ow_num(d, el[k], where, "outer", &r->outer) || ow_num(d, el[k], where, "level", &r->level))
            return -1;
    }
    /* The cells (absent or null: no table) and the table. */
    if (ow_key(d, root, "artifact", "cells", &cells)) return -1;
    if (cells && d->s[cells] != 'n') {
        if (ow_type(d, cells, '{', "artifact", "cells")
            || ow_edges(d, cells, "r2_edges", &w->r2_edges, &w->n_r2, el, OPTIMIS_WEIGHTS_MAX_EDGES)
            || ow_edges(d, cells, "r3_edges", &w->r3_edges, &w->n_r3, el, OPTIMIS_WEIGHTS_MAX_EDGES - w->n_r2)
            || ow_count(d, cells, "cells", "phi_bins", 4294967295.0, &phi_bins))
            return -1;
        if (phi_bins == 0) return OW_ERR("cells.phi_bins must be at least 1");
        w->phi_bins = (unsigned)phi_bins;
        if (w->n_r2 * w->n_r3 > OPTIMIS_WEIGHTS_MAX_CELLS || phi_bins > OPTIMIS_WEIGHTS_MAX_CELLS
            || (ncells = w->n_r2 * w->n_r3 * phi_bins) > OPTIMIS_WEIGHTS_MAX_CELLS)
            return OW_ERR("cells: more than %d cells", OPTIMIS_WEIGHTS_MAX_CELLS);
    }
    if (ow_table(d, root, w, ncells, el)) return -1;
    /* The heuristics and the provenance. */
    if (ow_array(d, root, "artifact", "heuristics", 1, el, OPTIMIS_WEIGHTS_MAX_HEURISTICS, &count)) return -1;
    for (w->n_heuristics = (int)count, k = 0; k < count; k++) {
        snprintf(where, sizeof where, "heuristics[%lu]", (unsigned long)k);
        if (ow_heuristic(d, el[k], where, &w->heuristics[k])) return -1;
    }
    if (ow_need(d, root, "artifact", "provenance", '{', &at)
        || ow_str(d, at, "provenance", "fingerprint", w->fingerprint, sizeof w->fingerprint))
        return -1;
    if (w->kind == OPTIMIS_KIND_HEURISTIC && (w->n_heuristics != 1 || w->table))
        return OW_ERR("a heuristic artifact holds one heuristic and no table");
    if (w->kind != OPTIMIS_KIND_HEURISTIC && !w->table) return OW_ERR("a table or a stack needs its table");
    return 0;
}

/* The artifact in s[0..n) into *w: the text checked whole, then the artifact as WeightFunction::new
 * checks it (src/sim/weights/function.rs). */
static int ow_parse(const char *s, size_t n, optimis_weights *w, char *err, size_t errlen) {
    ow_doc doc, *d = &doc;
    size_t end, *el;
    int r;
    doc.s = s; doc.n = n; doc.err = err; doc.errlen = errlen;
    memset(w, 0, sizeof *w);
    if (err && errlen) err[0] = '\0';
    if (!(end = ow_value(d, 0, 0))) return -1;
    if (ow_ws(d, end) != n) return OW_ERR("text after the JSON value at byte %lu", (unsigned long)ow_ws(d, end));
    if (!(el = (size_t *)malloc(OPTIMIS_WEIGHTS_MAX_EDGES * sizeof *el))) return OW_ERR("out of memory");
    r = ow_artifact(d, ow_ws(d, 0), w, el);
    free(el);
    if (r) optimis_weights_free(w);
    return r;
}

OPTIMIS_WEIGHTS_DEF void optimis_weights_free(optimis_weights *w) {
    if (!w) return;
    free(w->r2_edges);
    free(w->r3_edges);
    free(w->table);
    memset(w, 0, sizeof *w);
}

OPTIMIS_WEIGHTS_DEF int optimis_weights_load_string(const char *json, optimis_weights *out, char *err, size_t errlen) {
    return ow_parse(json, strlen(json), out, err, errlen);
}

OPTIMIS_WEIGHTS_DEF int optimis_weights_load_file(const char *path, optimis_weights *out, char *err, size_t errlen) {
    FILE *f;
    char *text = NULL, *grown;
    size_t n = 0, cap = 0;
    int r = 0;
    memset(out, 0, sizeof *out);
    if (!(f = fopen(path, "rb"))) {
        if (err && errlen) snprintf(err, errlen, "%s: %s", path, strerror(errno));
        return -1;
    }
    do { /* read it whole, in a buffer doubled from 64 KiB up to the bound (and a byte for the NUL) */
        if (n == cap) {
            cap = cap ? 2 * cap : (size_t)1 << 16;
            if (cap > (size_t)OPTIMIS_WEIGHTS_MAX_BYTES + 1) cap = (size_t)OPTIMIS_WEIGHTS_MAX_BYTES + 1;
            if (n == cap) { r = 2; break; }
            if (!(grown = (char *)realloc(text, cap + 1))) { r = 3; break; }
            text = grown;
        }
        n += fread(text + n, 1, cap - n, f);
    } while (n == cap);
    if (!r && ferror(f)) r = 1;
    fclose(f);
    if (r) {
        if (err && errlen)
            snprintf(err, errlen, "%s: %s", path,
                     r == 1 ? "cannot be read" : r == 2 ? "larger than the artifact's bound" : "out of memory");
        free(text);
        return -1;
    }
    text[n] = '\0';
    r = ow_parse(text, n, out, err, errlen);
    if (r && err && errlen) { /* the file's name before the message */
        size_t len = strlen(path);
        if (len + 2 < errlen) {
            memmove(err + len + 2, err, errlen - len - 2);
            err[errlen - 1] = '\0';
            memcpy(err, path, len);
            memcpy(err + len, ": ", 2);
        }
    }
    free(text);
    return r;
}

/* ---- The evaluator (src/sim/weights/function.rs). */

/* The last k with edges[k] <= r (0 for r below the first edge, or NaN). */
static size_t ow_bin(const double *edges, size_t n, double r) {
    size_t lo = 0, hi = n;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (edges[mid] <= r) lo = mid + 1; else hi = mid;
    }
    return lo > 0 ? lo - 1 : 0;
}

/* The balance heuristic's weight of technique m for the technique densities p. */
static double ow_balance(const double p[3], int m) {
    double total = p[0] + p[1] + p[2];
    return p[m] / total;
}

/* A surrogate probability min(1, A p). */
static double ow_hit(double area, double p) { return fmin(area * p, 1.0); }

/* Heuristic h's weight of a merge by technique m (model/heuristics.rs: Sharing, effective_counts). */
static double ow_heuristic_weight(const optimis_heuristic *h, int m, const optimis_path *p) {
    double q[3], pc[3], pl[3], cx2, lx3, lx2;
    int k;
    if (!h->techniques[m]) return 0.0;
    q[0] = h->techniques[0] ? p->light_x2 * p->light_x1 : 0.0;
    q[1] = h->techniques[1] ? p->camera_x2 * p->light_x2 : 0.0;
    q[2] = h->techniques[2] ? p->camera_x2 * p->camera_x3 : 0.0;
    switch (h->formula) {
    case OPTIMIS_ONE_TECHNIQUE: return h->technique == m ? 1.0 : 0.0;
    case OPTIMIS_SWITCH: return (p->r3 <= h->radius ? 1 : 2) == m ? 1.0 : 0.0;
    case OPTIMIS_BALANCE: return ow_balance(q, m);
    case OPTIMIS_POWER:
        for (k = 0; k < 3; k++) q[k] = pow(q[k], h->exponent);
        return ow_balance(q, m);
    case OPTIMIS_CORRELATION_AWARE:
        /* Surrogate probabilities of re-sampling the camera prefix and the light sub-path. */
        cx2 = ow_hit(h->area, p->camera_x2);
        lx3 = ow_hit(h->area, p->light_start);
        lx2 = lx3 * ow_hit(h->area, p->light_x2);
        pc[0] = 1.0; pc[1] = cx2; pc[2] = cx2 * ow_hit(h->area, p->camera_x3);
        pl[0] = lx2 * ow_hit(h->area, p->light_x1); pl[1] = lx2; pl[2] = lx3;
        for (k = 0; k < 3; k++) { /* the effective count n_k times p_k */
            double own = 1.0 - pc[k] * pl[k];
            double shared = own + (h->camera_paths - 1.0) * pc[k] * (1.0 - pl[k])
                            + (h->light_paths - 1.0) * pl[k] * (1.0 - pc[k]);
            double n = shared > 0.0 ? own / shared : 1.0 / (h->light_paths * h->camera_paths);
            q[k] = n * q[k];
        }
        return ow_balance(q, m);
    }
    return (double)NAN;
}

OPTIMIS_WEIGHTS_DEF double optimis_weights_eval(const optimis_weights *w, int technique, const optimis_path *path) {
    double table = 0.0, sum = 0.0;
    int h;
    if (technique < 0 || technique > 2) return (double)NAN;
    if (w->table) {
        size_t nphi = w->phi_bins, iphi = 0, cell;
        if (nphi > 1) {
            double x = path->phi / OW_PI * (double)nphi;
            iphi = x >= 0.0 ? (x < (double)nphi ? (size_t)x : nphi - 1) : 0; /* NaN: 0 */
            if (iphi > nphi - 1) iphi = nphi - 1;
        }
        cell = ow_bin(w->r2_edges, w->n_r2, path->r2) * w->n_r3 + ow_bin(w->r3_edges, w->n_r3, path->r3);
        cell = cell * nphi + iphi;
        table = w->table[cell][technique];
    }
    for (h = 0; h < w->n_heuristics; h++)
        sum += w->heuristics[h].beta * ow_heuristic_weight(&w->heuristics[h], technique, path);
    return table + sum;
}

/* ---- The model scene's join paths (src/sim/weights/densities.rs). */

/* The lobe's solid-angle pdf q(theta) = g(theta) theta / sin(theta), g = exp(-theta^2/2b^2)/(2 pi b^2). */
static double ow_lobe_pdf(double beta, double theta) {
    double g = exp(-theta * theta / (2.0 * beta * beta)) / (2.0 * OW_PI * beta * beta);
    double ratio = theta < 1e-4 ? 1.0 + theta * theta / 6.0 : theta / sin(theta);
    return g * ratio;
}

OPTIMIS_WEIGHTS_DEF void optimis_model_path(const optimis_weights *w, const double x2[2], const double x3[2],
                                            const double x3l[2], optimis_path *out) {
    const optimis_scene *sc = &w->scene;
    double u[3], v[3], a[3], b[3], c[3], d1, d2, d1_2, d2_2, theta, q, r3l, cross, dot;
    int k;
    u[0] = x2[0]; u[1] = x2[1]; u[2] = sc->l2;
    v[0] = x3[0] - x2[0]; v[1] = x3[1] - x2[1]; v[2] = sc->l3;
    d1 = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    d2 = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (k = 0; k < 3; k++) { a[k] = u[k] / d1; b[k] = v[k] / d2; }
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
    theta = atan2(sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]), a[0] * b[0] + a[1] * b[1] + a[2] * b[2]);
    q = ow_lobe_pdf(sc->beta_rad, theta);
    d1_2 = d1 * d1;
    d2_2 = d2 * d2;
    out->camera_x2 = sc->l2 * sc->l2 / (OW_PI * d1_2 * d1_2);
    out->camera_x3 = q * sc->l3 / (d2_2 * d2);
    out->light_x2 = sc->l3 * sc->l3 / (OW_PI * d2_2 * d2_2);
    out->light_x1 = q * sc->l2 / (d1_2 * d1);
    out->light_start = 0.0; /* level / flux of the first ring holding |x3l| */
    r3l = sqrt(x3l[0] * x3l[0] + x3l[1] * x3l[1]);
    for (k = 0; k < sc->n_rings; k++)
        if (r3l >= sc->rings[k].inner && r3l < sc->rings[k].outer) {
            out->light_start = sc->rings[k].level / sc->flux;
            break;
        }
    cross = x2[0] * x3[1] - x2[1] * x3[0];
    dot = x2[0] * x3[0] + x2[1] * x3[1];
    out->r2 = sqrt(x2[0] * x2[0] + x2[1] * x2[1]);
    out->r3 = sqrt(x3[0] * x3[0] + x3[1] * x3[1]);
    out->phi = atan2(fabs(cross), dot);
}

#endif /* OPTIMIS_WEIGHTS_IMPLEMENTED */
#endif /* OPTIMIS_WEIGHTS_IMPLEMENTATION */
