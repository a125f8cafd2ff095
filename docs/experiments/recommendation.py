#!/usr/bin/env python3
"""Issue 21's acceptance measurements: is the recommendation something to act on in one run?

For each seed, a short run's result (its recommended row, reported RMS and SE, its weights) is
scored on an independent long run of another seed with `optimis evaluate`; the weights' ±2 SE
intervals are compared with the same fitted row (same λ) fitted on the long run; every per-path
row's z against its expected luminance at R is collected. Everything goes through the `optimis`
command line, so anyone can rerun it:

    python3 docs/experiments/recommendation.py --optimis target/release/optimis \
        --work /tmp/rec --seeds 1-30 --iterations 10000 --long 1000000 [--set solver.fixed.w0=null]

Prints one JSON summary on stdout (and keeps every document under --work).
"""
import argparse
import json
import math
import os
import statistics
import subprocess
import sys


def run(cmd, **kw):
    return subprocess.run(cmd, check=True, capture_output=True, text=True, **kw).stdout


def seeds(text):
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--optimis", default="target/release/optimis")
    ap.add_argument("--work", required=True)
    ap.add_argument("--seeds", default="1-30")
    ap.add_argument("--iterations", type=int, default=10000)
    ap.add_argument("--long", type=int, default=1000000)
    ap.add_argument("--long-seed", type=int, default=1000)
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--weights", action="store_true", help="also measure the weights' coverage")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    sets = [x for s in a.set for x in ("--set", s)]
    base = [a.optimis, "run", "--preset", "paper-table1", "--quiet"] + sets
    long_doc = os.path.join(a.work, f"long-{a.long_seed}-{a.long}.json")
    if not os.path.exists(long_doc):
        run(base + ["--iterations", str(a.long), "--seed", str(a.long_seed), "--out", long_doc])
    out = {"iterations": a.iterations, "long": a.long, "long_seed": a.long_seed, "set": a.set, "seeds": []}
    long_reports = {}
    for s in seeds(a.seeds):
        doc = os.path.join(a.work, f"run-{s}-{a.iterations}.json")
        res = os.path.join(a.work, f"result-{s}-{a.iterations}.json")
        if not os.path.exists(res):
            if os.path.exists(doc):
                # A kept run: re-solve its moments (what a change of the solver needs).
                text = run([a.optimis, "report", doc, "--json"] + solver_flags(a.set))
            else:
                text = run(base + ["--iterations", str(a.iterations), "--seed", str(s), "--json", "--out", doc])
            open(res, "w").write(text)
        r = json.load(open(res))
        rec = r["recommended"]
        row = next(x for x in r["noise_table"] if x["strategy"] == rec["strategy"])
        ev = json.loads(run([a.optimis, "evaluate", long_doc, "--weights", res, "--json"]))
        delivered = ev["evaluated"]["rms_percent"]
        switch = next(v["row"]["rms_percent"] for v in ev["versus"] if v["row"]["strategy"] == "switch")
        entry = {
            "seed": s,
            "recommended": rec["strategy"],
            "lambda": rec["lambda"],
            "reported": row["rms_percent"],
            "reported_se": row["rms_percent_stderr"],
            "delivered": delivered,
            "delivered_se": ev["evaluated"]["rms_percent_stderr"],
            "switch_delivered": switch,
            "z": {x["strategy"]: x["z"] for x in r["noise_table"] if x.get("z") is not None},
            "optimal_cv": next(x["rms_percent"] for x in r["noise_table"] if x["strategy"] == "optimal_cv"),
            "warnings": [w["code"] for w in r["warnings"]],
        }
        if a.weights:
            entry["weights"] = weight_coverage(a, doc, long_doc, r, long_reports)
        entry["fitted"] = fitted_rows(a, doc, long_doc, r)
        out["seeds"].append(entry)
        print(f"seed {s}: {rec['strategy']} reported {row['rms_percent']:.2f} ± {row['rms_percent_stderr'] or 0:.2f}, "
              f"delivered {delivered:.2f} (switch {switch:.2f})", file=sys.stderr)
    out["summary"] = summary(out["seeds"])
    json.dump(out, sys.stdout, indent=1)
    print()


def solver_flags(sets):
    """The `--set solver.…` options as `report --solver` JSON (the only ones this script passes)."""
    solver = {}
    for s in sets:
        key, _, value = s.partition("=")
        path = key.split(".")
        assert path[0] == "solver", f"only solver.… settings can re-solve a kept run, got {s}"
        node = solver
        for p in path[1:-1]:
            node = node.setdefault(p, {})
        node[path[-1]] = json.loads(value)
    return ["--solver", json.dumps(solver)] if solver else []


def fitted_rows(a, doc, long_doc, result):
    """Every cross-fitted row chosen by cross-validation (optimal_cv, optimal_stacked): its reported
    RMS ± SE and what its weights (fitted on all iterations at its λ, heuristics included) deliver on
    the long run."""
    out = {}
    for name in ("optimal_cv", "optimal_stacked"):
        row = next((x for x in result["noise_table"] if x["strategy"] == name and x["lambda"] is not None), None)
        if row is None or row["rms_percent"] is None:
            continue
        table = json.loads(run([a.optimis, "report", doc, "--json", "--weights-lambda", str(row["lambda"]),
                                "--weights-of", "optimal" if name == "optimal_cv" else name]))
        given = {"weights": table["weights"],
                 "heuristics": [{"strategy": h["strategy"], "beta": h["beta"]} for h in row["heuristics"]]}
        path = doc + f".{name}.weights.json"
        json.dump(given, open(path, "w"))
        ev = json.loads(run([a.optimis, "evaluate", long_doc, "--weights", path, "--json"]))
        out[name] = {"reported": row["rms_percent"], "reported_se": row["rms_percent_stderr"],
                     "delivered": ev["evaluated"]["rms_percent"], "unstable": row["unstable"], "lambda": row["lambda"]}
    return out


def weight_coverage(a, doc, long_doc, result, cache):
    """Per fitted row with a table (optimal_cv, optimal_stacked): its weights at its λ, ±2 SE, against
    the same row at the same λ fitted on the long run; counted over cells with a data SE."""
    counts = {}
    for name in ("optimal_cv", "optimal_stacked"):
        row = next((x for x in result["noise_table"] if x["strategy"] == name and x["lambda"] is not None), None)
        if row is None:
            continue
        lam = row["lambda"]
        args = ["report", "--json", "--weights-lambda", str(lam), "--weights-of",
                "optimal" if name == "optimal_cv" else name]
        short = json.loads(run([a.optimis] + args[:1] + [doc] + args[1:]))
        key = (name, lam)
        if key not in cache:
            cache[key] = json.loads(run([a.optimis] + args[:1] + [long_doc] + args[1:]))
        ref = cache[key]
        inside = total = smoothed = 0
        for c, l in zip(short["weights"], ref["weights"]):
            if c["w1_stderr"] is None:
                smoothed += 1
                continue
            for m in ("w0", "w1", "w2"):
                se = c[f"{m}_stderr"]
                if se is None or se == 0.0:
                    continue
                total += 1
                inside += abs(c[m] - l[m]) <= 2.0 * se
        counts[name] = {"lambda": lam, "covered": inside, "total": total, "cells_without_se": smoothed}
    return counts


def summary(rows):
    n = len(rows)
    rep = [r["reported"] for r in rows]
    dl = [r["delivered"] for r in rows]
    diff = [r["reported"] - r["delivered"] for r in rows]
    se = [r["reported_se"] for r in rows if r["reported_se"] is not None]
    within = sum(abs(r["reported"] - r["delivered"]) <= 2.5 * (r["reported_se"] or 0) for r in rows)
    worse = sum(r["delivered"] > r["switch_delivered"] for r in rows)
    z = {}
    for r in rows:
        for k, v in r["z"].items():
            z.setdefault(k, []).append(v)
    out = {
        "seeds": n,
        "recommended": {k: sum(r["recommended"] == k for r in rows) for k in sorted({r["recommended"] for r in rows})},
        "mean_reported_rms": statistics.mean(rep),
        "mean_reported_rms_se": statistics.stdev(rep) / math.sqrt(n) if n > 1 else None,
        "mean_delivered_rms": statistics.mean(dl),
        "mean_optimal_cv_rms": statistics.mean(r["optimal_cv"] for r in rows),
        "delivered_worse_than_switch": worse,
        "reported_within_2_5_se_of_delivered": within,
        "spread_of_reported_minus_delivered": statistics.stdev(diff) if n > 1 else None,
        "spread_of_delivered": statistics.stdev(dl) if n > 1 else None,
        "mean_reported_se": statistics.mean(se) if se else None,
        "z_within_1_96": {k: f"{sum(abs(x) < 1.96 for x in v)}/{len(v)}" for k, v in sorted(z.items())},
    }
    for name in ("optimal_cv", "optimal_stacked"):
        f = [r["fitted"][name] for r in rows if name in r.get("fitted", {})]
        if len(f) > 1:
            d = [x["reported"] - x["delivered"] for x in f]
            out[f"calibration_{name}"] = {
                "n": len(f),
                "mean_reported": statistics.mean(x["reported"] for x in f),
                "mean_delivered": statistics.mean(x["delivered"] for x in f),
                "mean_reported_se": statistics.mean(x["reported_se"] for x in f),
                "spread_of_reported": statistics.stdev(x["reported"] for x in f),
                "spread_of_delivered": statistics.stdev(x["delivered"] for x in f),
                "spread_of_reported_minus_delivered": statistics.stdev(d),
                "within_2_5_se": sum(abs(x["reported"] - x["delivered"]) <= 2.5 * x["reported_se"] for x in f),
                "delivered_worse_than_switch": sum(x["delivered"] > rows[0]["switch_delivered"] for x in f),
            }
    rep_se = [r["reported_se"] for r in rows if r["reported_se"] is not None]
    if len(rep_se) == n and n > 1:
        out["recommended_se_vs_spread_of_reported"] = statistics.mean(rep_se) / statistics.stdev(rep)
    w = [r.get("weights") for r in rows if r.get("weights")]
    if w:
        for name in ("optimal_cv", "optimal_stacked"):
            cov = [x[name] for x in w if name in x]
            if cov:
                out[f"weights_{name}"] = {
                    "covered": sum(c["covered"] for c in cov),
                    "total": sum(c["total"] for c in cov),
                    "cells_without_se": sum(c["cells_without_se"] for c in cov),
                }
    return out


if __name__ == "__main__":
    main()
