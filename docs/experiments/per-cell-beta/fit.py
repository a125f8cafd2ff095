"""Per-cell β for correlation_aware_planes23: does it lower the stacked optimum's RMS? (issue 21)

Reads the per-iteration tallies that `dump.patch` makes `optimis run` write (EXP_DUMP=DIR: one
file per worker thread, rows of f64: s, C^(m)_α for m = 0..2 and the K cells, the ten per-path
strategies' C_s, and correlation_aware_planes23's contribution per cell), and compares, with the
paper's w0 = 0:

  table  — w1 per cell (the optimal_cv family),
  stack  — table + β_switch·switch + β·correlation_aware_planes23 (optimal_stacked's family),
  cell   — table + β_switch·switch + β_α·correlation_aware_planes23 per cell α,

each at λ ∈ {0.1, 1} (the penalty of docs/model.md §7 on the table, and for `cell` also on β_α
across neighbouring cells), 10-fold cross-fitted (folds s mod 10) on each short run, and
"delivered": fitted on all of a short run, scored on the long run. RMS is sd/μ with μ the mean of
the three single-plane estimates of the run it is computed on (docs/model.md §7's J).

usage: python3 fit.py SHORT_DIR... --long LONG_DIR
"""
import glob
import sys

import numpy as np

K, N2, N3, NS = 52, 2, 26, 10
SWITCH, CA23 = 3, 9  # indices in PathStrategy::ALL


def load(d):
    rows = [np.fromfile(f, dtype="<f8").reshape(-1, 1 + 3 * K + NS + K) for f in sorted(glob.glob(d + "/*.bin"))]
    a = np.concatenate(rows)
    return a[np.argsort(a[:, 0])]


def columns(a):
    c = a[:, 1:1 + 3 * K].reshape(-1, 3, K)
    st = a[:, 1 + 3 * K:1 + 3 * K + NS]
    h = a[:, 1 + 3 * K + NS:]
    b = c[:, 2, :].sum(1)
    mu = sum(c[:, m, :].sum(1).mean() for m in range(3)) / 3
    return dict(s=a[:, 0].astype(np.int64), B=b, A1=c[:, 1, :] - c[:, 2, :], Hsw=st[:, SWITCH] - b,
                Hca=st[:, CA23] - b, G=h - c[:, 2, :], mu=mu, ca=st[:, CA23])


NEIGHBOURS = [(i2 * N3 + i3, j) for i2 in range(N2) for i3 in range(N3)
              for j in ([(i2 + 1) * N3 + i3] if i2 + 1 < N2 else []) + ([i2 * N3 + i3 + 1] if i3 + 1 < N3 else [])]


def design(d, family):
    return np.concatenate({"table": [d["A1"]], "stack": [d["A1"], d["Hsw"][:, None], d["Hca"][:, None]],
                           "cell": [d["A1"], d["G"], d["Hsw"][:, None]]}[family], 1)


def penalty(family):
    n = {"table": K, "stack": K + 2, "cell": 2 * K + 1}[family]
    r = np.zeros((n, n))
    for a, b in NEIGHBOURS:
        v = np.zeros(n); v[a], v[b] = 1, -1
        r += 2 * np.outer(v, v) if family != "cell" else np.outer(v, v)  # w1 and w2 = 1 − Σβ − w1
        if family == "cell":
            w = v.copy(); w[K + a], w[K + b] = 1, -1
            r += np.outer(w, w)  # w2 = 1 − β_α − w1: its difference moves with β_α's
            u = np.zeros(n); u[K + a], u[K + b] = 1, -1
            r += np.outer(u, u)  # β_α itself is smoothed like a table
    return r


def fit(z, b, mu, lam, r):
    zc, bc = z - z.mean(0), b - b.mean()
    s, sb = zc.T @ zc / (len(b) - 1), zc.T @ bc / (len(b) - 1)
    return np.linalg.solve(s / mu**2 + lam * r + 1e-12 * np.diag(np.diag(s) / mu**2 + 1e-30), -sb / mu**2)


def rms(c, mu):
    return 100 * c.std(ddof=1) / mu


def crossfit(d, family, lam, folds=10):
    z, r, out, f = design(d, family), penalty(family), np.empty(len(d["B"])), d["s"] % folds
    for k in range(folds):
        train = f != k
        out[~train] = d["B"][~train] + z[~train] @ fit(z[train], d["B"][train], d["mu"], lam, r)
    return rms(out, d["mu"])


def main():
    args = sys.argv[1:]
    long_dir = args[args.index("--long") + 1]
    shorts = [a for a in args if a not in ("--long", long_dir)]
    ref = columns(load(long_dir))
    print(f"long run: {len(ref['B'])} iterations, correlation_aware_planes23 {rms(ref['ca'], ref['mu']):.3f}%")
    for path in shorts:
        d = columns(load(path))
        out = [f"{path}: correlation_aware_planes23 {rms(d['ca'], d['mu']):.3f}"]
        for family in ("stack", "cell"):
            for lam in (0.1, 1.0):
                x = fit(design(d, family), d["B"], d["mu"], lam, penalty(family))
                delivered = rms(ref["B"] + design(ref, family) @ x, ref["mu"])
                out.append(f"{family}@{lam}: cross-fitted {crossfit(d, family, lam):.3f} delivered {delivered:.3f}")
        print(" | ".join(out), flush=True)


if __name__ == "__main__":
    main()
