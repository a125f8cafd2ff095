"""Variant heuristics stacked on optimal_stacked's family (scratch experiment, issue 21)."""
import glob, sys
import numpy as np
K, N2, N3, NS, NV = 52, 2, 26, 10, 8
SWITCH, CA23 = 3, 9
NAMES = ["ca/16", "ca/4", "ca*4", "ca*16", "ca*100", "powerCA", "n^2", "n^0.5"]

def load(d):
    rows = [np.fromfile(f, dtype="<f8").reshape(-1, 1 + 3 * K + NS + NV) for f in sorted(glob.glob(d + "/*.bin"))]
    a = np.concatenate(rows)
    return a[np.argsort(a[:, 0])]

def columns(a):
    c = a[:, 1:1 + 3 * K].reshape(-1, 3, K)
    st = a[:, 1 + 3 * K:1 + 3 * K + NS]
    v = a[:, 1 + 3 * K + NS:]
    b = c[:, 2, :].sum(1)
    mu = sum(c[:, m, :].sum(1).mean() for m in range(3)) / 3
    return dict(s=a[:, 0].astype(np.int64), B=b, A1=c[:, 1, :] - c[:, 2, :], Hsw=st[:, SWITCH] - b,
                Hca=st[:, CA23] - b, V=v - b[:, None], v=v, mu=mu, ca=st[:, CA23], sw=st[:, SWITCH])

NEIGHBOURS = [(i2 * N3 + i3, j) for i2 in range(N2) for i3 in range(N3)
              for j in ([(i2 + 1) * N3 + i3] if i2 + 1 < N2 else []) + ([i2 * N3 + i3 + 1] if i3 + 1 < N3 else [])]

def design(d, extra):
    cols = [d["A1"], d["Hsw"][:, None], d["Hca"][:, None]] + [d["V"][:, [e]] for e in extra]
    return np.concatenate(cols, 1)

def penalty(n):
    r = np.zeros((n, n))
    for a, b in NEIGHBOURS:
        v = np.zeros(n); v[a], v[b] = 1, -1
        r += 2 * np.outer(v, v)
    return r

def fit(z, b, mu, lam, r):
    zc, bc = z - z.mean(0), b - b.mean()
    s, sb = zc.T @ zc / (len(b) - 1), zc.T @ bc / (len(b) - 1)
    return np.linalg.solve(s / mu**2 + lam * r + 1e-12 * np.diag(np.diag(s) / mu**2 + 1e-30), -sb / mu**2)

def rms(c, mu): return 100 * c.std(ddof=1) / mu

def crossfit(d, z, lam, folds=10):
    r, out, f = penalty(z.shape[1]), np.empty(len(d["B"])), d["s"] % folds
    for k in range(folds):
        train = f != k
        out[~train] = d["B"][~train] + z[~train] @ fit(z[train], d["B"][train], d["mu"], lam, r)
    return rms(out, d["mu"])

def main():
    args = sys.argv[1:]
    long_dir = args[args.index("--long") + 1]
    shorts = [a for a in args if a not in ("--long", long_dir)]
    ref = columns(load(long_dir))
    print(f"long: {len(ref['B'])} it; CA23 {rms(ref['ca'], ref['mu']):.3f} switch {rms(ref['sw'], ref['mu']):.3f} " +
          " ".join(f"{n} {rms(ref['v'][:, i], ref['mu']):.3f}" for i, n in enumerate(NAMES)), flush=True)
    fams = [("stack", [])] + [(n, [i]) for i, n in enumerate(NAMES)] + [("area4", [0, 1, 2, 3, 4]), ("all", list(range(NV)))]
    tot = {}
    for path in shorts:
        d = columns(load(path))
        out = [path]
        for name, extra in fams:
            for lam in (0.1, 1.0):
                z = design(d, extra)
                x = fit(z, d["B"], d["mu"], lam, penalty(z.shape[1]))
                dl = rms(ref["B"] + design(ref, extra) @ x, ref["mu"])
                cf = crossfit(d, z, lam)
                tot.setdefault((name, lam), []).append((cf, dl))
                out.append(f"{name}@{lam}: {cf:.3f}/{dl:.3f}")
        print(" | ".join(out), flush=True)
    for (name, lam), v in tot.items():
        v = np.array(v)
        print(f"{name:8s} λ={lam}: mean cross-fitted {v[:,0].mean():.3f} delivered {v[:,1].mean():.3f}")

if __name__ == "__main__":
    main()
