#!/usr/bin/env python3
"""Are the standard errors of `optimis predict` and `optimis budget` calibrated? (issue 21, item 7)

For each seed, a short run of the paper's preset with noise components predicts the noise table at
another budget (N_F, N_B). Each predicted figure is compared with what it claims to measure:

* a fixed row's (or a heuristic's) predicted RMS with the RMS of a long direct run at that budget
  (another seed);
* a re-fitted row's predicted RMS (optimal_cv, optimal_stacked, and the row recommended there)
  with the RMS its re-fitted weights deliver on that long run (`optimis evaluate`).

A calibrated SE matches the spread between seeds of (predicted − truth). `optimis budget` is run
on every source too (with fixed per-path costs, so that only the statistics vary): its headline
speed-up's SE is compared with the spread of the speed-up between seeds and — with
`--truth-iterations N` — with the speed-up the headline strategy really has at the budget it
chose: a direct run of N iterations at every budget chosen gives that strategy's RMS there (its
own cross-fitted figure, fitted on N iterations), and the paper's switch at (10⁷, 100) its RMS
from a direct run of N iterations as well. Everything goes through the command
line, so anyone can rerun it:

    python3 docs/experiments/prediction_calibration.py --optimis target/release/optimis \
        --work /tmp/pcal --seeds 1-24 --iterations 20000 --long 1000000 \
        --light-paths 10000000 --camera-paths 1000

Prints one JSON summary on stdout (and keeps every document under --work).
"""
import argparse
import json
import math
import os
import statistics
import subprocess


def run(cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def seeds(text):
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def rows(table):
    return {r["strategy"]: r for r in table if r.get("rms_percent") is not None}


def summary(pairs):
    """pairs: (reported, reported_se, truth, truth_se) per seed."""
    diffs = [p - t for p, _, t, _ in pairs]
    spread = statistics.stdev(diffs)
    truth_se = statistics.mean(ts for *_, ts in pairs)
    # What the seeds' spread says the prediction's own SE is: the truth's noise is common to every
    # seed (one long run), so it shifts the differences but does not widen their spread.
    se = statistics.mean(s for _, s, _, _ in pairs)
    within2 = sum(abs(p - t) <= 2 * math.hypot(s, ts) for p, s, t, ts in pairs)
    return {
        "n": len(pairs),
        "mean_reported": statistics.mean(p for p, *_ in pairs),
        "truth": statistics.mean(t for _, _, t, _ in pairs),
        "truth_se": truth_se,
        "mean_bias": statistics.mean(diffs),
        "mean_se": se,
        "spread": spread,
        "se_over_spread": se / spread,
        "within_2se": within2,
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--optimis", default="target/release/optimis")
    ap.add_argument("--work", required=True)
    ap.add_argument("--seeds", default="1-24")
    ap.add_argument("--iterations", type=int, default=20000)
    ap.add_argument("--long", type=int, default=1000000)
    ap.add_argument("--long-seed", type=int, default=5000)
    ap.add_argument("--light-paths", type=int, default=10000000)
    ap.add_argument("--camera-paths", type=int, default=1000)
    ap.add_argument("--truth-iterations", type=int, default=0)
    ap.add_argument("--costs", default="7.0e-9,6.45e-6,9.5e-4",
                    help="seconds per light path, per camera path and pixel, per iteration (budget)")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    o = a.optimis
    lc, cc, ic = a.costs.split(",")
    costs = ["--light-cost", lc, "--camera-cost", cc, "--iteration-cost", ic]
    budget = ["--light-paths", str(a.light_paths), "--camera-paths", str(a.camera_paths)]
    long_doc = os.path.join(a.work, f"long-{a.camera_paths}-{a.long_seed}.json")
    long_res = long_doc.replace(".json", ".result.json")
    if not os.path.exists(long_res):
        text = run([o, "run", "--preset", "paper-table1", "--set", f"light_paths={a.light_paths}",
                    "--set", f"camera_paths={a.camera_paths}", "--iterations", str(a.long),
                    "--seed", str(a.long_seed), "--quiet", "--json", "--out", long_doc])
        open(long_res, "w").write(text)
    truth = rows(json.load(open(long_res))["noise_table"])
    per_row, budgets, entries, truths = {}, [], [], []
    for s in seeds(a.seeds):
        doc = os.path.join(a.work, f"comp-{s}-{a.iterations}.json")
        if not os.path.exists(doc):
            run([o, "run", "--preset", "paper-table1", "--spec", "examples/specs/noise-components.json",
                 "--iterations", str(a.iterations), "--seed", str(s), "--quiet", "--out", doc])
        pred = json.loads(run([o, "predict", doc, "--json"] + budget))
        predicted = rows(pred["noise_table"])
        entry = {"seed": s, "recommended": pred["recommended"]["strategy"], "rows": {}}
        rec = pred["recommended"]["strategy"]
        for name, row in predicted.items():
            if row["lambda"] is None:
                if name not in truth:
                    continue
                t = truth[name]
                pair = (row["rms_percent"], row["rms_percent_stderr"], t["rms_percent"], t["rms_percent_stderr"])
            elif name == rec:
                # The re-fitted row recommended there: score its predicted weights on the long run.
                wfile = os.path.join(a.work, f"weights-{s}.json")
                json.dump({"weights": pred["weights"], "heuristics": row["heuristics"]}, open(wfile, "w"))
                ev = json.loads(run([o, "evaluate", long_doc, "--weights", wfile, "--json"]))["evaluated"]
                pair = (row["rms_percent"], row["rms_percent_stderr"], ev["rms_percent"], ev["rms_percent_stderr"])
            else:
                continue
            per_row.setdefault(name, []).append(pair)
            entry["rows"][name] = pair
            if name == rec:
                per_row.setdefault("recommended", []).append(pair)
        # Fixed per-path costs (those of the documented run), so that only the statistics vary.
        plan = json.loads(run([o, "budget", doc, "--json"] + costs))
        best = next(b for b in plan["best"] if b["strategy"] == plan["headline"])
        entry["budget"] = {k: best.get(k) for k in ("strategy", "budget", "speedup", "speedup_stderr", "at_edge")}
        budgets.append((best["speedup"], best["speedup_stderr"], best["strategy"]))
        if a.truth_iterations:
            b = best["budget"]
            direct = rows(direct_run(a, b["light_paths"], b["camera_paths"])["noise_table"])
            paper = rows(direct_run(a, 10000000, 100)["noise_table"])["switch"]
            t = lambda f, n: float(lc) * f + float(cc) * n * 1e6 + float(ic)
            truth_r = direct[best["strategy"]]["rms_percent"]
            true_up = (paper["rms_percent"] ** 2 * t(10000000, 100)) / (truth_r ** 2 * t(b["light_paths"], b["camera_paths"]))
            entry["budget"]["true_rms"] = truth_r
            entry["budget"]["true_speedup"] = true_up
            truths.append((best["speedup"], best["speedup_stderr"], true_up, 0.0))
        entries.append(entry)
    out = {
        "iterations": a.iterations,
        "budget": {"light_paths": a.light_paths, "camera_paths": a.camera_paths},
        "long": a.long,
        "long_seed": a.long_seed,
        "rows": {k: summary(v) for k, v in per_row.items() if len(v) >= 3},
        "seeds": entries,
    }
    if len(budgets) >= 3:
        # The headline strategy may differ between seeds; the speed-up is compared as it is shown.
        ups = [b for b, _, _ in budgets]
        out["budget_speed_up"] = {
            "n": len(ups),
            "strategies": sorted({s for *_, s in budgets if s}),
            "mean": statistics.mean(ups),
            "spread": statistics.stdev(ups),
            "mean_se": statistics.mean(e for _, e, _ in budgets),
            "se_over_spread": statistics.mean(e for _, e, _ in budgets) / statistics.stdev(ups),
        }
    if len(truths) >= 3:
        out["budget_speed_up_vs_direct"] = summary(truths)
    print(json.dumps(out, indent=1))


def direct_run(a, light_paths, camera_paths):
    """A direct run at (light_paths, camera_paths), kept under --work: its result (noise table)."""
    res = os.path.join(a.work, f"direct-{light_paths}-{camera_paths}-{a.truth_iterations}.result.json")
    if not os.path.exists(res):
        text = run([a.optimis, "run", "--preset", "paper-table1", "--set", f"light_paths={light_paths}",
                    "--set", f"camera_paths={camera_paths}", "--iterations", str(a.truth_iterations),
                    "--seed", str(a.long_seed + 1), "--quiet", "--json",
                    "--out", res.replace(".result.json", ".json")])
        open(res, "w").write(text)
    return json.load(open(res))


if __name__ == "__main__":
    main()
