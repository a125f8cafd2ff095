#!/usr/bin/env python3
"""Acceptance study of the radii opt-in (issue 44): one run at R tallies the moments at every R′ < R.

A job with `"radii": [R′…]` reports, per radius, a noise table with each row's bias (the report's
`radii` field). This script checks those figures against runs made directly at R′, and
the plan to a target RMSE (`optimis budget --target-rmse`) against direct runs at the budgets it
proposes. Four parts, each from the command line only, so that anyone can rerun it:

A. Predictions at R′ vs direct runs. Wide runs (R = 0.02, radii 0.003, 0.005, 0.01, noise
   components) on seeds 101…110 against direct runs at each R′ on seeds 201…210 (same iterations).
   Per row, R′ and seed pair: z = (rms_wide − rms_direct)/√(se_wide² + se_direct²). Accepted when
   |z| ≤ 2.5 in ≥ 90% of the pairs for every per-path row and R′ (fitted rows shown too). The SE
   calibration: the spread (std) of each row's RMS over the wide runs against their mean SE.
B. Bias. One long direct run per R′ (seed 301): each per-path row's Monte-Carlo bias
   100·(L̂ − L)/L ± 100·se(L̂)/L against the quadrature bias the wide runs report at R′,
   z = (mc − q)/se_mc; accepted when |z| ≤ 2.5 for every per-path row.
C. The plan to a target RMSE (1%) of the first wide run: its best point (strategy S, R*, B*) and
   two neighbours of the same strategy and radius (N_F one and two half-decade steps below, same
   N_B). A direct run at each gives S's RMS ± SE; with the plan's costs and the run's merges the
   measured time to target is t·max(1, rms²/(P² − b²)), compared with the plan's prediction.
   Beside it: the best point replicated (every wide run's plan, further direct runs), the speed-up
   over the paper's setup measured (part A's direct runs at its radius), and one direct run far
   from the runs' budget, where several plans put their best (--far-point).
D. Timing of the opt-in: wall clock (and CPU) of `optimis run` at R = 0.02 with noise components,
   with the radii and without, long and short runs alternating, per-iteration ratio.

    python3 docs/experiments/radii_study.py --optimis target/release/optimis \\
        --work /tmp/radii-study --out docs/experiments/radii --parts A,B,C,D

Every run's result (`--json`) and moments document stay under --work (reused when present: rerun
with other --parts to complete the study); the figures go to OUT/radii_study.json and the tables
to OUT/summary.md (any text after the line `<!-- remarks -->` in an existing summary is kept).
"""
import argparse
import collections
import json
import math
import os
import resource
import shlex
import statistics
import subprocess
import time

FIXED = ["plane1", "plane2", "plane3", "switch", "balance", "power", "correlation_aware",
         "balance_planes23", "power_planes23", "correlation_aware_planes23"]
FITTED = ["optimal_cv", "optimal_stacked", "optimal_holdout", "switch_corrected",
          "balance_planes23_corrected", "power_planes23_corrected",
          "correlation_aware_planes23_corrected"]
Z_MAX = 2.5
SCENE = []  # the default preset is the paper's scene (paper-table1)


def seeds(text):
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def fmt_radius(r):
    return ("%g" % r).replace(".", "p")


def run_timed(cmd):
    """Runs cmd; its stdout, wall seconds and CPU seconds (user + sys of the child)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return out, wall, cpu


class Runner:
    """Cached runs: WORK/NAME.result.json (the printed report), WORK/NAME.json (moments)."""

    def __init__(self, optimis, work, log):
        self.o, self.work, self.log = optimis, work, log
        self.commands = {}

    def run(self, name, args, out_doc=True):
        res = os.path.join(self.work, name + ".result.json")
        meta = os.path.join(self.work, name + ".meta.json")
        cmd = [self.o, "run"] + SCENE + ["--quiet", "--json"] + args
        if out_doc:
            cmd += ["--out", os.path.join(self.work, name + ".json")]
        self.commands[name] = cmd
        if not os.path.exists(res):
            self.log(f"run {name}: {' '.join(cmd)}")
            text, wall, cpu = run_timed(cmd)
            open(res + ".tmp", "w").write(text)
            os.replace(res + ".tmp", res)
            json.dump({"command": cmd, "wall_seconds": wall, "cpu_seconds": cpu,
                       "loadavg": os.getloadavg()}, open(meta, "w"))
            self.log(f"  done in {wall:.1f} s (cpu {cpu:.1f} s)")
        return json.load(open(res)), json.load(open(meta))


def wide_args(a, seed, iterations):
    return ["--set", f"merge_radius={a.wide_radius}", "--set", f"radii={json.dumps(a.radii)}",
            "--set", "noise_components=true", "--iterations", str(iterations), "--seed", str(seed)]


def direct_args(radius, seed, iterations, components=True, extra=()):
    args = ["--set", f"merge_radius={radius}"]
    if components:
        args += ["--set", "noise_components=true"]
    return args + list(extra) + ["--iterations", str(iterations), "--seed", str(seed)]


def radius_rows(report, radius):
    entry = next(x for x in report["radii"] if math.isclose(x["merge_radius"], radius))
    return entry, {r["strategy"]: r for r in entry["rows"]}


def table_rows(report):
    return {r["strategy"]: r for r in report["noise_table"] if not r.get("in_sample")}


def stats_z(zs):
    inside = sum(abs(z) <= Z_MAX for z in zs)
    return {"z": zs, "n": len(zs), "within": inside, "fraction_within": inside / len(zs),
            "mean_z": statistics.mean(zs), "sd_z": statistics.stdev(zs) if len(zs) > 1 else None,
            "max_abs_z": max(abs(z) for z in zs)}


# ---------------------------------------------------------------- A
def part_a(a, R):
    wides = {s: R.run(f"wide-{s}", wide_args(a, s, a.iterations))[0] for s in seeds(a.wide_seeds)}
    directs = {}
    for r in a.radii:
        for s in seeds(a.direct_seeds):
            directs[(r, s)] = R.run(f"direct-{fmt_radius(r)}-{s}", direct_args(r, s, a.iterations))[0]
    out = {"wide_seeds": seeds(a.wide_seeds), "direct_seeds": seeds(a.direct_seeds),
           "iterations": a.iterations, "rows": {}}
    pairs = list(zip(seeds(a.wide_seeds), seeds(a.direct_seeds)))
    for r in a.radii:
        per_r = {}
        for name in FIXED + FITTED:
            zs, w_rms, w_se, d_rms, d_se, lum_z = [], [], [], [], [], []
            for sw, sd in pairs:
                w = radius_rows(wides[sw], r)[1].get(name)
                d = table_rows(directs[(r, sd)]).get(name)
                if not w or not d or w["rms_percent_stderr"] is None or d["rms_percent_stderr"] is None:
                    continue
                zs.append((w["rms_percent"] - d["rms_percent"]) / math.hypot(w["rms_percent_stderr"], d["rms_percent_stderr"]))
                w_rms.append(w["rms_percent"]); w_se.append(w["rms_percent_stderr"])
                d_rms.append(d["rms_percent"]); d_se.append(d["rms_percent_stderr"])
                # Informative: both estimate the same expectation at R′ (a fitted row: each its own fit).
                lum_z.append((w["luminance"] - d["luminance"]) / math.hypot(w["luminance_stderr"], d["luminance_stderr"]))
            if not zs:
                continue
            e = stats_z(zs)
            e.update({
                "kind": "per-path" if name in FIXED else "fitted",
                "accepted": e["fraction_within"] >= 0.9,
                "luminance_z": lum_z, "luminance_within": sum(abs(z) <= Z_MAX for z in lum_z),
                "luminance_mean_z": statistics.mean(lum_z),
                "wide_rms": w_rms, "wide_se": w_se, "direct_rms": d_rms, "direct_se": d_se,
                "wide_mean_rms": statistics.mean(w_rms), "direct_mean_rms": statistics.mean(d_rms),
                # SE calibration: the spread of the RMS between seeds against the mean reported SE.
                "wide_spread": statistics.stdev(w_rms), "wide_mean_se": statistics.mean(w_se),
                "wide_spread_over_se": statistics.stdev(w_rms) / statistics.mean(w_se),
                "direct_spread": statistics.stdev(d_rms), "direct_mean_se": statistics.mean(d_se),
                "direct_spread_over_se": statistics.stdev(d_rms) / statistics.mean(d_se),
                # Both runs estimate the same RMS: the spread over all 2×10 runs against their mean SE.
                "pooled_spread_over_se": statistics.stdev(w_rms + d_rms) / statistics.mean(w_se + d_se),
            })
            per_r[name] = e
        out["rows"][str(r)] = per_r
    fixed = [(r, n, e) for r, rows in out["rows"].items() for n, e in rows.items() if e["kind"] == "per-path"]
    out["accepted"] = all(e["accepted"] for *_, e in fixed)
    out["failures"] = [{"radius": r, "strategy": n, "within": e["within"], "n": e["n"]}
                       for r, n, e in fixed if not e["accepted"]]
    all_z = [z for *_, e in fixed for z in e["z"]]
    out["pooled_per_path"] = {"n": len(all_z), "mean_z": statistics.mean(all_z),
                              "sd_z": statistics.stdev(all_z),
                              "fraction_within": sum(abs(z) <= Z_MAX for z in all_z) / len(all_z)}
    # The quadrature bias of every per-path row at every R′ (identical between the wide runs?).
    q = {}
    for r in a.radii:
        for name in FIXED:
            vals = [radius_rows(wides[s], r)[1][name]["bias_percent"] for s in wides]
            q.setdefault(str(r), {})[name] = {"bias_percent": vals[0],
                                              "bias_percent_stderr": radius_rows(wides[seeds(a.wide_seeds)[0]], r)[1][name]["bias_percent_stderr"],
                                              "spread_between_seeds": max(vals) - min(vals)}
    out["quadrature_bias"] = q
    out["merges_per_iteration"] = {str(r): statistics.mean(sum(radius_rows(wides[s], r)[0]["merges_per_iteration"]) for s in wides)
                                   for r in a.radii + [a.wide_radius]}
    return out


# ---------------------------------------------------------------- B
def part_b(a, R, quadrature):
    out = {"seed": a.long_seed, "radii": {}}
    for r in a.radii:
        n = a.long[str(r)]
        rep, meta = R.run(f"long-{fmt_radius(r)}-{a.long_seed}-{n}", direct_args(r, a.long_seed, n))
        L = rep["reference_luminance"]
        rows, acc = {}, True
        for name, row in table_rows(rep).items():
            if name not in FIXED + FITTED:
                continue
            mc = 100 * (row["luminance"] - L) / L
            se = 100 * row["luminance_stderr"] / L
            e = {"kind": "per-path" if name in FIXED else "fitted", "mc_bias_percent": mc, "mc_se": se,
                 "rms_percent": row["rms_percent"], "rms_percent_stderr": row["rms_percent_stderr"]}
            if name in FIXED:
                q = quadrature[str(r)][name]["bias_percent"]
                own = 100 * (row["expected_luminance"] - L) / L if row.get("expected_luminance") else None
                e.update({"quadrature_bias_percent": q, "direct_run_expected_bias_percent": own,
                          "z": (mc - q) / se, "accepted": abs((mc - q) / se) <= Z_MAX})
                acc &= e["accepted"]
            rows[name] = e
        out["radii"][str(r)] = {"iterations": n, "wall_seconds": meta["wall_seconds"],
                                "reference_luminance": L, "rows": rows, "accepted": acc}
    out["accepted"] = all(x["accepted"] for x in out["radii"].values())
    return out


# ---------------------------------------------------------------- C
def seconds_per_iteration(costs, nf, nb, merges):
    return (costs["light_path"] * nf + costs["camera_path"] * nb * costs["pixels"] + costs["iteration"]
            + costs["merge"] * merges * costs["pixels"])


def part_c(a, R):
    first = seeds(a.wide_seeds)[0]
    doc = os.path.join(a.work, f"wide-{first}.json")
    cmd = [a.optimis, "budget", doc, "--target-rmse", str(a.target), "--json"]
    plan_file = os.path.join(a.work, f"budget-wide-{first}.json")
    if not os.path.exists(plan_file):
        open(plan_file, "w").write(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    plan = json.load(open(plan_file))
    costs, best = plan["costs"], plan["best"]
    S, Rs, B = best["strategy"], best["merge_radius"], best["budget"]
    same = [p for p in plan["best_strategy_points"]
            if p["strategy"] == S and math.isclose(p["merge_radius"], Rs)
            and p["budget"]["camera_paths"] == B["camera_paths"]]
    # N_F one and two half-decade steps below B* (the grid's integers round 10^k/2).
    points = [best]
    for steps in (1, 2):
        want = B["light_paths"] / 10 ** (steps / 2)
        p = min(same, key=lambda p: abs(math.log10(p["budget"]["light_paths"] / want)))
        if abs(math.log10(p["budget"]["light_paths"] / want)) < 0.05:
            points.append(p)
    fixed_row = S in FIXED
    out = {"command": cmd, "target_rmse_percent": a.target, "costs": costs, "strategy": S,
           "merge_radius": Rs, "points": [],
           "plan": {k: plan[k] for k in ("best", "at_own_radius", "paper", "speedup_over_paper",
                                        "speedup_over_paper_stderr", "speedup_over_own_radius",
                                        "speedup_over_own_radius_stderr", "progressive",
                                        "out_of_reach", "notes")},
           "best_strategy_points": plan["best_strategy_points"]}
    P = a.target
    for i, p in enumerate(points):
        nf, nb = p["budget"]["light_paths"], p["budget"]["camera_paths"]
        m = a.check_iterations[i]
        extra = ["--set", f"light_paths={nf}", "--set", f"camera_paths={nb}"]
        rep, meta = R.run(f"check-{fmt_radius(Rs)}-{nf}-{nb}-{a.check_seed + i}-{m}",
                          direct_args(Rs, a.check_seed + i, m, components=False, extra=extra), out_doc=False)
        row = table_rows(rep)[S]
        L = rep["reference_luminance"]
        if fixed_row:
            b = 100 * (row["expected_luminance"] - L) / L
            b_se = 0.0
        else:
            b, b_se = p["bias_percent"], p["bias_percent_stderr"]
        merges = sum(v["mean"] for v in rep["merges_per_iteration"].values())
        t = seconds_per_iteration(costs, nf, nb, merges)
        rms, rms_se = row["rms_percent"], row["rms_percent_stderr"]
        room = P * P - b * b
        iters = rms * rms / room
        if iters > 1:
            T, T_se = t * iters, t * 2 * rms * rms_se / room
        else:
            T, T_se = t, 0.0
        out["points"].append({
            "budget": p["budget"], "iterations_run": m, "seed": a.check_seed + i,
            "wall_seconds": meta["wall_seconds"],
            "predicted": {k: p[k] for k in ("rms_percent", "rms_percent_stderr", "bias_percent",
                                            "bias_percent_stderr", "iterations", "seconds_per_iteration",
                                            "seconds_to_target", "seconds_to_target_stderr")},
            "measured": {"rms_percent": rms, "rms_percent_stderr": rms_se,
                         "rms_relative_se": rms_se / rms, "bias_percent": b, "bias_percent_stderr": b_se,
                         "luminance_bias_percent": 100 * (row["luminance"] - L) / L,
                         "luminance_bias_se": 100 * row["luminance_stderr"] / L,
                         "merges_per_iteration": merges, "seconds_per_iteration": t,
                         "iterations": iters, "seconds_to_target": T, "seconds_to_target_stderr": T_se},
            "z_time": (p["seconds_to_target"] - T) / math.hypot(p["seconds_to_target_stderr"], T_se),
        })
    # Replication of the best point: every wide run's plan predicts S's RMS at B*, R* (spread of the
    # prediction), and direct runs on further seeds measure it (spread of the truth).
    rep_pred, rep_meas = [], []
    for s in seeds(a.wide_seeds):
        f_plan = os.path.join(a.work, f"budget-wide-{s}.json")
        if not os.path.exists(f_plan):
            open(f_plan, "w").write(subprocess.run(
                [a.optimis, "budget", os.path.join(a.work, f"wide-{s}.json"), "--target-rmse", str(a.target), "--json"],
                check=True, capture_output=True, text=True).stdout)
        pl = json.load(open(f_plan))
        p = [q for q in pl["candidates"] + pl["best_strategy_points"] if q["strategy"] == S
             and math.isclose(q["merge_radius"], Rs) and q["budget"] == B]
        rep_pred.append({"seed": s, "plan_best": [pl["best"]["strategy"], pl["best"]["merge_radius"], pl["best"]["budget"]],
                         "best_seconds_to_target": pl["best"]["seconds_to_target"],
                         "best_seconds_to_target_stderr": pl["best"]["seconds_to_target_stderr"],
                         "speedup_over_paper": pl["speedup_over_paper"],
                         "speedup_over_paper_stderr": pl["speedup_over_paper_stderr"],
                         "speedup_over_own_radius": pl["speedup_over_own_radius"],
                         "speedup_over_own_radius_stderr": pl["speedup_over_own_radius_stderr"],
                         "rms_percent": p[0]["rms_percent"] if p else None,
                         "rms_percent_stderr": p[0]["rms_percent_stderr"] if p else None})
    m = a.check_iterations[0]
    for s in seeds(a.replicate_seeds) if a.replicate_seeds else []:
        extra = ["--set", f"light_paths={B['light_paths']}", "--set", f"camera_paths={B['camera_paths']}"]
        rep, _ = R.run(f"check-{fmt_radius(Rs)}-{B['light_paths']}-{B['camera_paths']}-{s}-{m}",
                       direct_args(Rs, s, m, components=False, extra=extra), out_doc=False)
        row = table_rows(rep)[S]
        rep_meas.append({"seed": s, "rms_percent": row["rms_percent"], "rms_percent_stderr": row["rms_percent_stderr"]})
    rep_meas.insert(0, {"seed": a.check_seed, "rms_percent": out["points"][0]["measured"]["rms_percent"],
                        "rms_percent_stderr": out["points"][0]["measured"]["rms_percent_stderr"]})
    pv = [x["rms_percent"] for x in rep_pred if x["rms_percent"] is not None]
    mv = [x["rms_percent"] for x in rep_meas]
    out["replication_best_point"] = {
        "predicted": rep_pred, "measured": rep_meas,
        "predicted_mean": statistics.mean(pv), "predicted_spread": statistics.stdev(pv),
        "predicted_mean_se": statistics.mean(x["rms_percent_stderr"] for x in rep_pred if x["rms_percent"] is not None),
        "measured_mean": statistics.mean(mv), "measured_spread": statistics.stdev(mv) if len(mv) > 1 else None,
        "measured_mean_se": statistics.mean(x["rms_percent_stderr"] for x in rep_meas),
    }
    rb = out["replication_best_point"]
    rb["z_means"] = (rb["predicted_mean"] - rb["measured_mean"]) / math.hypot(
        rb["predicted_spread"] / math.sqrt(len(pv)), (rb["measured_spread"] or rb["measured_mean_se"]) / math.sqrt(len(mv)))
    # Far point: where several wide runs' plans put their best (an R′ < R and N_F 1.5 decades above
    # the runs' own): each plan's prediction of its best strategy there against one direct run.
    if a.far_point:
        fr, fnf, fnb = a.far_point.split(":")
        fr, fnf, fnb = float(fr), int(fnf), int(fnb)
        extra = ["--set", f"light_paths={fnf}", "--set", f"camera_paths={fnb}"]
        rep, meta = R.run(f"far-{fmt_radius(fr)}-{fnf}-{fnb}-{a.far_seed}-{a.far_iterations}",
                          direct_args(fr, a.far_seed, a.far_iterations, components=False, extra=extra), out_doc=False)
        direct = table_rows(rep)
        far_t = seconds_per_iteration(costs, fnf, fnb, sum(v["mean"] for v in rep["merges_per_iteration"].values()))
        far = {"seconds_per_iteration": far_t, "merge_radius": fr, "budget": {"light_paths": fnf, "camera_paths": fnb}, "seed": a.far_seed,
               "iterations": a.far_iterations, "wall_seconds": meta["wall_seconds"],
               "direct": {n: {"rms_percent": direct[n]["rms_percent"], "rms_percent_stderr": direct[n]["rms_percent_stderr"]}
                          for n in ("optimal_stacked", "optimal_cv", "correlation_aware_planes23") if n in direct},
               "plans": []}
        for s in seeds(a.wide_seeds):
            pl = json.load(open(os.path.join(a.work, f"budget-wide-{s}.json")))
            q = [x for x in pl["best_strategy_points"] if math.isclose(x["merge_radius"], fr)
                 and x["budget"] == far["budget"]]
            if not q:
                continue
            q = q[0]
            d = direct[q["strategy"]]
            far["plans"].append({
                "seed": s, "strategy": q["strategy"], "is_plan_best": pl["best"]["merge_radius"] == fr and pl["best"]["budget"] == far["budget"],
                "predicted_rms": q["rms_percent"], "predicted_rms_se": q["rms_percent_stderr"], "supported": q["supported"],
                "predicted_seconds_to_target": q["seconds_to_target"], "predicted_seconds_to_target_se": q["seconds_to_target_stderr"],
                "measured_rms": d["rms_percent"], "measured_rms_se": d["rms_percent_stderr"],
                "z": (q["rms_percent"] - d["rms_percent"]) / math.hypot(q["rms_percent_stderr"], d["rms_percent_stderr"]),
                # Its time to target with the direct run's RMS (the plan's bias and costs).
                "measured_seconds_to_target": far_t * max(1.0, d["rms_percent"] ** 2 / (P * P - q["bias_percent"] ** 2)),
                "measured_seconds_to_target_se": far_t * 2 * d["rms_percent"] * d["rms_percent_stderr"] / (P * P - q["bias_percent"] ** 2)})
        out["far_point"] = far
    # The speed-up over the paper's setup, measured: the best point's time from the mean of its direct
    # runs, the paper's (its strategy at its radius and budget) from part A's direct runs there.
    pp = plan["paper"]
    if (any(math.isclose(pp["merge_radius"], r) for r in a.radii) and pp["budget"] == {"light_paths": 10000000, "camera_paths": 100}
            and a.paper_direct):
        r = next(r for r in a.radii if math.isclose(pp["merge_radius"], r))
        reps = [json.load(open(os.path.join(a.work, f"direct-{fmt_radius(r)}-{s}.result.json"))) for s in seeds(a.direct_seeds)]
        rms = [table_rows(x)[pp["strategy"]]["rms_percent"] for x in reps]
        mp = statistics.mean(sum(v["mean"] for v in x["merges_per_iteration"].values()) for x in reps)
        tp = seconds_per_iteration(costs, 10000000, 100, mp)
        room_p = P * P - pp["bias_percent"] ** 2
        rp, rp_se = statistics.mean(rms), statistics.stdev(rms) / math.sqrt(len(rms))
        Tp, Tp_se = tp * rp * rp / room_p, tp * 2 * rp * rp_se / room_p
        mv = [x["rms_percent"] for x in rep_meas]
        rb_, rb_se = statistics.mean(mv), statistics.stdev(mv) / math.sqrt(len(mv))
        t0 = out["points"][0]["measured"]["seconds_per_iteration"]
        room_b = P * P - out["points"][0]["measured"]["bias_percent"] ** 2
        Tb, Tb_se = t0 * rb_ * rb_ / room_b, t0 * 2 * rb_ * rb_se / room_b
        out["measured_speedup_over_paper"] = {
            "paper_rms_mean": rp, "paper_rms_mean_se": rp_se, "paper_runs": len(rms), "paper_seconds_per_iteration": tp,
            "paper_seconds_to_target": Tp, "paper_seconds_to_target_se": Tp_se,
            "best_rms_mean": rb_, "best_rms_mean_se": rb_se, "best_runs": len(mv),
            "best_seconds_to_target": Tb, "best_seconds_to_target_se": Tb_se,
            "speedup": Tp / Tb, "speedup_se": Tp / Tb * math.hypot(Tp_se / Tp, Tb_se / Tb)}
    pr = [q["predicted"]["seconds_to_target"] for q in out["points"]]
    me = [q["measured"]["seconds_to_target"] for q in out["points"]]
    order = lambda v: sorted(range(len(v)), key=lambda k: v[k])
    out["predicted_order"], out["measured_order"] = order(pr), order(me)
    out["order_holds"] = order(pr) == order(me)
    return out


# ---------------------------------------------------------------- D
def part_d(a):
    doc = os.path.join(a.work, "timing.json")
    base = [a.optimis, "run"] + SCENE + ["--quiet", "--json", "--out", doc, "--set",
                                         f"merge_radius={a.wide_radius}", "--set", "noise_components=true",
                                         "--seed", str(a.timing_seed)]
    variants = {"radii": ["--set", f"radii={json.dumps(a.radii)}"], "plain": []}
    times = {(v, n): [] for v in variants for n in (a.timing_long, a.timing_short)}
    commands = {}
    for rep in range(a.timing_reps):
        for n in (a.timing_long, a.timing_short):
            for v, extra in variants.items():
                cmd = base + extra + ["--iterations", str(n)]
                commands[f"{v}-{n}"] = cmd
                load = os.getloadavg()[0]
                _, wall, cpu = run_timed(cmd)
                times[(v, n)].append({"wall": wall, "cpu": cpu, "load1": load})
                a.log(f"timing {v} {n} rep {rep}: {wall:.2f} s wall, {cpu:.2f} s cpu, load {load:.2f}")
    out = {"commands": commands, "reps": a.timing_reps, "long": a.timing_long, "short": a.timing_short,
           "runs": {f"{v}-{n}": x for (v, n), x in times.items()}}
    return analyse_d(out)


def analyse_d(out):
    """Per-iteration times (long − short) and the ratio radii/plain, from the stored runs."""
    runs, long_, short = out["runs"], out["long"], out["short"]
    dn = long_ - short
    for clock in ("wall", "cpu"):
        per = {}
        for v in ("radii", "plain"):
            lo = [x[clock] for x in runs[f"{v}-{long_}"]]
            sh = [x[clock] for x in runs[f"{v}-{short}"]]
            it = [(l - s) / dn for l, s in zip(lo, sh)]
            per[v] = {"long_mean": statistics.mean(lo), "long_sd": statistics.stdev(lo),
                      "short_mean": statistics.mean(sh), "short_sd": statistics.stdev(sh),
                      "per_iteration": statistics.mean(it), "per_iteration_se": statistics.stdev(it) / math.sqrt(len(it)),
                      "per_iteration_per_rep": it}
        r = per["radii"]["per_iteration"] / per["plain"]["per_iteration"]
        r_se = r * math.hypot(per["radii"]["per_iteration_se"] / per["radii"]["per_iteration"],
                              per["plain"]["per_iteration_se"] / per["plain"]["per_iteration"])
        ratios = [a / b for a, b in zip(per["radii"]["per_iteration_per_rep"], per["plain"]["per_iteration_per_rep"])]
        # Paired: each repetition's four runs ran back to back, so their ratio shares the machine's load.
        out[clock] = {"variants": per, "ratio": r, "ratio_se": r_se, "ratio_per_rep": ratios,
                      "paired_ratio": statistics.mean(ratios),
                      "paired_ratio_se": statistics.stdev(ratios) / math.sqrt(len(ratios))}
    return out


# ---------------------------------------------------------------- summary
def f(x, d=2):
    return "—" if x is None else f"{x:.{d}f}"


def pm(x, s, d=2):
    return f"{f(x, d)} ± {f(s, d)}"


def summary_md(a, res, commands):
    L = []
    w = L.append
    w("# Radii acceptance study (issue 44)")
    w("")
    w(f"Date: {a.date}. Binary: `{a.optimis}` built from commit {a.commit}. Script: "
      "`docs/experiments/radii_study.py`; every figure in `radii_study.json`. Preset `paper-table1` "
      "(restricted engine, N_F = 10^7, N_B = 100). SEs are one standard error; z thresholds |z| ≤ 2.5.")
    w("")
    w("Reproduce:")
    w("")
    w("```")
    w(f"python3 docs/experiments/radii_study.py --optimis {a.optimis} --work {a.work} --out {a.out} --parts A,B,C,D "
      f"--long {a.long_text} --check-iterations {','.join(map(str, a.check_iterations))}")
    w("```")
    if "A" in res:
        A = res["A"]
        w("")
        w(f"## A. The wide run's figures at R′ vs direct runs at R′")
        w("")
        w(f"Wide runs: seeds {A['wide_seeds'][0]}–{A['wide_seeds'][-1]}, direct runs: seeds "
          f"{A['direct_seeds'][0]}–{A['direct_seeds'][-1]} (paired in order), {A['iterations']:,} iterations each.")
        w("")
        w("```")
        w(shlex.join(commands.get(f"wide-{A['wide_seeds'][0]}", [])))
        w(shlex.join(commands.get(f"direct-{fmt_radius(a.radii[0])}-{A['direct_seeds'][0]}", [])))
        w("```")
        w("")
        w(f"**Acceptance (per-path rows, |z| ≤ 2.5 in ≥ 90% of the pairs for every row and R′): "
          f"{'PASS' if A['accepted'] else 'FAIL'}.** Pooled over all per-path (row, R′, seed): "
          f"mean z {A['pooled_per_path']['mean_z']:+.2f}, sd {A['pooled_per_path']['sd_z']:.2f}, "
          f"{100 * A['pooled_per_path']['fraction_within']:.1f}% within 2.5 (n = {A['pooled_per_path']['n']}).")
        if A["failures"]:
            w("Failing (row, R′): " + ", ".join(f"{x['strategy']} at {x['radius']} ({x['within']}/{x['n']})" for x in A["failures"]) + ".")
        for r, rows in A["rows"].items():
            w("")
            w(f"### R′ = {r}")
            w("")
            w("| row | kind | wide RMS % (mean ± mean SE) | direct RMS % (mean ± mean SE) | within 2.5 | mean z | sd z | max abs z | wide spread / mean SE | direct spread / mean SE | pooled spread / mean SE | L̂: within 2.5 (mean z) |")
            w("|---|---|---|---|---|---|---|---|---|---|---|---|")
            for n, e in rows.items():
                w(f"| {n} | {e['kind']} | {pm(e['wide_mean_rms'], e['wide_mean_se'])} | {pm(e['direct_mean_rms'], e['direct_mean_se'])} "
                  f"| {e['within']}/{e['n']}{'' if e['accepted'] else ' ✗'} | {e['mean_z']:+.2f} | {f(e['sd_z'])} | {e['max_abs_z']:.2f} "
                  f"| {e['wide_spread_over_se']:.2f} | {e['direct_spread_over_se']:.2f} | {e['pooled_spread_over_se']:.2f} "
                  f"| {e['luminance_within']}/{e['n']} ({e['luminance_mean_z']:+.2f}) |")
        w("")
        w("The last column compares the luminances L̂ (wide at R′ vs direct), z = (L̂_w − L̂_d)/√(se_w² + se_d²): "
          "informative, and for a fitted row each run's own fit.")
        w("A spread/SE ratio from 10 runs is itself uncertain by about ±24% (one SE, normal data; more for "
          "heavy-tailed rows, whose spread over a few runs is usually below its true value); the pooled one "
          "(wide and direct runs together, which estimate the same RMS) by about ±16%.")
    if "B" in res:
        B = res["B"]
        w("")
        w("## B. Bias at R′: long direct runs vs the quadrature")
        w("")
        w(f"Seed {B['seed']}. MC bias = 100·(L̂ − L)/L ± 100·se(L̂)/L, L = reference luminance "
          f"(L·10⁵ = {next(iter(B['radii'].values()))['reference_luminance'] * 1e5:.4f}); quadrature = the wide runs' "
          f"radii rows (seed {res['A']['wide_seeds'][0] if 'A' in res else '?'}; identical in all wide runs); z = (MC − q)/se_MC.")
        w(f"**Acceptance (|z| ≤ 2.5 for every per-path row): {'PASS' if B['accepted'] else 'FAIL'}.**")
        w("")
        w("```")
        for r in B["radii"]:
            k = f"long-{fmt_radius(float(r))}-{B['seed']}-{B['radii'][r]['iterations']}"
            w(shlex.join(commands.get(k, [])))
        w("```")
        for r, x in B["radii"].items():
            w("")
            w(f"### R′ = {r} ({x['iterations']:,} iterations, {x['wall_seconds']:.0f} s)")
            w("")
            w("| row | MC bias % | quadrature bias % | z | RMS % |")
            w("|---|---|---|---|---|")
            for n, e in x["rows"].items():
                if e["kind"] != "per-path":
                    continue
                w(f"| {n} | {pm(e['mc_bias_percent'], e['mc_se'], 3)} | {e['quadrature_bias_percent']:+.3g} "
                  f"| {e['z']:+.2f}{'' if e['accepted'] else ' ✗'} | {pm(e['rms_percent'], e['rms_percent_stderr'])} |")
            w("")
            w("Fitted rows (informative; their bias is L̂ − L): " + "; ".join(
                f"{n} {pm(e['mc_bias_percent'], e['mc_se'], 3)}" for n, e in x["rows"].items() if e["kind"] == "fitted") + ".")
    if "C" in res:
        C = res["C"]
        pl = C["plan"]
        w("")
        w(f"## C. The plan to a {C['target_rmse_percent']}% RMSE (wide run seed {seeds(a.wide_seeds)[0]})")
        w("")
        w("```")
        w(shlex.join(C["command"]))
        w("```")
        w("")
        c = C["costs"]
        w(f"Costs ({c.get('source')}): t_F = {c['light_path']:g} s, t_B = {c['camera_path']:g} s, t_0 = {c['iteration']:g} s, "
          f"t_M = {c['merge']:g} s, P = {c['pixels']:g}. Measured time to target = t·max(1, rms²/(P² − b²)) with t from these costs "
          f"and the direct run's merges per iteration; SE by the delta method from the RMS SE (the bias SE is 2·10⁻⁷% for a per-path row).")
        w("")
        w(f"Strategy S = {C['strategy']}, R* = {C['merge_radius']}.")
        w("")
        w("| point | N_F | N_B | iterations run | predicted RMS % | measured RMS % | bias % (pred / meas) | predicted s/it | measured s/it | predicted time to target (s) | measured time to target (s) | z |")
        w("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for i, p in enumerate(C["points"]):
            pr, me = p["predicted"], p["measured"]
            w(f"| {'best' if i == 0 else f'best − {i}·½ decade'} | {p['budget']['light_paths']:,} | {p['budget']['camera_paths']} | {p['iterations_run']:,} "
              f"| {pm(pr['rms_percent'], pr['rms_percent_stderr'])} | {pm(me['rms_percent'], me['rms_percent_stderr'])} "
              f"| {pr['bias_percent']:+.4f} / {me['bias_percent']:+.4f} | {pr['seconds_per_iteration']:.1f} | {me['seconds_per_iteration']:.1f} "
              f"| {pm(pr['seconds_to_target'], pr['seconds_to_target_stderr'], 0)} | {pm(me['seconds_to_target'], me['seconds_to_target_stderr'], 0)} | {p['z_time']:+.2f} |")
        w("")
        w(f"Predicted order (fastest first, by point index): {C['predicted_order']}; measured: {C['measured_order']} — "
          f"**{'holds' if C['order_holds'] else 'does NOT hold'}**.")
        w("")
        rb = C["replication_best_point"]
        w(f"Replication of the best point ({C['strategy']} at R* = {C['merge_radius']}, {C['points'][0]['budget']['light_paths']:,} × "
          f"{C['points'][0]['budget']['camera_paths']}): the plans of all {len(rb['predicted'])} wide runs predict its RMS "
          f"{rb['predicted_mean']:.2f}% (spread {rb['predicted_spread']:.2f}, mean SE {rb['predicted_mean_se']:.2f}); "
          f"{len(rb['measured'])} direct runs (seeds {', '.join(str(x['seed']) for x in rb['measured'])}, "
          f"{C['points'][0]['iterations_run']:,} iterations) measure {rb['measured_mean']:.2f}% "
          f"(spread {f(rb['measured_spread'])}, mean SE {rb['measured_mean_se']:.2f}); z of the means {rb['z_means']:+.2f}.")
        w("")
        w("| source | seeds | RMS % per seed |")
        w("|---|---|---|")
        w("| plans (predicted) | " + f"{rb['predicted'][0]['seed']}–{rb['predicted'][-1]['seed']} | " + ", ".join(
            pm(x['rms_percent'], x['rms_percent_stderr']) for x in rb['predicted'] if x['rms_percent'] is not None) + " |")
        w("| direct runs | " + ", ".join(str(x['seed']) for x in rb['measured']) + " | " + ", ".join(
            pm(x['rms_percent'], x['rms_percent_stderr']) for x in rb['measured']) + " |")
        key = lambda x: f"{x['plan_best'][0]} at R′ = {x['plan_best'][1]}, {x['plan_best'][2]['light_paths']:,} × {x['plan_best'][2]['camera_paths']}"
        bests = collections.Counter(key(x) for x in rb["predicted"])
        w("")
        w("The wide runs' plans choose as best: " + "; ".join(f"{b} ({n}×)" for b, n in bests.most_common()) + ".")
        w("")
        w("| wide seed | plan's best | its time to target (s) | speed-up over the paper | over the run's own radius |")
        w("|---|---|---|---|---|")
        for x in rb["predicted"]:
            w(f"| {x['seed']} | {key(x)} | {pm(x['best_seconds_to_target'], x['best_seconds_to_target_stderr'], 0)} "
              f"| {pm(x['speedup_over_paper'], x['speedup_over_paper_stderr'])} | {pm(x['speedup_over_own_radius'], x['speedup_over_own_radius_stderr'], 3)} |")
        if "far_point" in C:
            fp = C["far_point"]
            w("")
            w(f"Far from the runs' budget — R′ = {fp['merge_radius']}, {fp['budget']['light_paths']:,} × {fp['budget']['camera_paths']}, "
              f"where {sum(x['is_plan_best'] for x in fp['plans'])} of the wide runs' plans put their best: a direct run (seed {fp['seed']}, "
              f"{fp['iterations']:,} iterations, {fp['wall_seconds']:.0f} s) measures " + ", ".join(
                  f"{n} {pm(v['rms_percent'], v['rms_percent_stderr'])}%" for n, v in fp["direct"].items()) + ".")
            w("")
            w("| wide seed | plan's strategy | plan's best? | predicted RMS % | measured RMS % | z | predicted time to target (s) | measured time to target (s) |")
            w("|---|---|---|---|---|---|---|---|")
            for x in fp["plans"]:
                w(f"| {x['seed']} | {x['strategy']} | {'yes' if x['is_plan_best'] else 'no'} | {pm(x['predicted_rms'], x['predicted_rms_se'])}"
                  f"{'' if x['supported'] else ' (unsupported)'} | {pm(x['measured_rms'], x['measured_rms_se'])} | {x['z']:+.2f} "
                  f"| {pm(x['predicted_seconds_to_target'], x['predicted_seconds_to_target_se'], 0)} "
                  f"| {pm(x['measured_seconds_to_target'], x['measured_seconds_to_target_se'], 0)} |")
        w("")
        w("The plan's headline points:")
        w("")
        w("| point | strategy | R′ | N_F | N_B | RMS % | bias % | s/it | time to target (s) |")
        w("|---|---|---|---|---|---|---|---|---|")
        for k in ("best", "at_own_radius", "paper"):
            p = pl[k]
            w(f"| {k} | {p['strategy']} | {p['merge_radius']} | {p['budget']['light_paths']:,} | {p['budget']['camera_paths']} "
              f"| {pm(p['rms_percent'], p['rms_percent_stderr'])} | {pm(p['bias_percent'], p['bias_percent_stderr'], 4)} "
              f"| {p['seconds_per_iteration']:.1f} | {pm(p['seconds_to_target'], p['seconds_to_target_stderr'], 0)} |")
        g = pl["progressive"]
        if g:
            w(f"| progressive | {g['strategy']} | {g['first_radius']:g} → {g['last_radius']:.4g} (α = {g['alpha']:.3f}{', floored' if g['floored'] else ''}) "
              f"| {g['budget']['light_paths']:,} | {g['budget']['camera_paths']} | — | — | — | {pm(g['seconds_to_target'], g['seconds_to_target_stderr'], 0)} ({g['iterations']:.0f} iterations) |")
        w("")
        w(f"Speed-up of the best point over the paper's setup: {pm(pl['speedup_over_paper'], pl['speedup_over_paper_stderr'])}; "
          f"over the best at the run's own radius: {pm(pl['speedup_over_own_radius'], pl['speedup_over_own_radius_stderr'])}.")
        if "measured_speedup_over_paper" in C:
            ms = C["measured_speedup_over_paper"]
            w("")
            w(f"Measured instead (plan's costs, direct runs' RMS and merges): the paper's setup ({pl['paper']['strategy']} at "
              f"{pl['paper']['merge_radius']}, 10^7 × 100) from part A's {ms['paper_runs']} direct runs there, RMS "
              f"{pm(ms['paper_rms_mean'], ms['paper_rms_mean_se'])}% → {pm(ms['paper_seconds_to_target'], ms['paper_seconds_to_target_se'], 0)} s; "
              f"the best point from its {ms['best_runs']} direct runs, RMS {pm(ms['best_rms_mean'], ms['best_rms_mean_se'])}% → "
              f"{pm(ms['best_seconds_to_target'], ms['best_seconds_to_target_se'], 0)} s; speed-up {pm(ms['speedup'], ms['speedup_se'])}.")
        if pl["notes"]:
            w("")
            w("Plan notes: " + " / ".join(map(str, pl["notes"])))
        w("")
        w("Out of reach (bias ≥ target): " + ", ".join(f"{x['strategy']} at {x['merge_radius']} ({x['bias_percent']:+.2f}%)" for x in pl["out_of_reach"]) + ".")
    if "D" in res:
        D = res["D"]
        w("")
        w("## D. Cost of the opt-in")
        w("")
        w("```")
        w(shlex.join(D["commands"][f"radii-{D['long']}"]))
        w(shlex.join(D["commands"][f"plain-{D['long']}"]))
        w("```")
        w("")
        w(f"{D['reps']} alternating repetitions of {D['long']:,} and {D['short']:,} iterations each; per iteration = "
          f"(T_long − T_short)/{D['long'] - D['short']:,}. The machine was shared (load average noted per run in the JSON).")
        w("")
        w("| clock | variant | T_long (s) | T_short (s) | per iteration (ms) |")
        w("|---|---|---|---|---|")
        for clock in ("wall", "cpu"):
            for v, x in D[clock]["variants"].items():
                w(f"| {clock} | {v} | {pm(x['long_mean'], x['long_sd'])} (sd) | {pm(x['short_mean'], x['short_sd'])} (sd) "
                  f"| {pm(1e3 * x['per_iteration'], 1e3 * x['per_iteration_se'], 3)} |")
        w("")
        w("Per-iteration ratio radii/plain (paired: the mean of the repetitions' ratios ± its SE; unpaired: the ratio of "
          "the mean per-iteration times, whose SE includes the load's drift between repetitions):")
        w("")
        w("| clock | paired ratio | per repetition | unpaired ratio |")
        w("|---|---|---|---|")
        for clock in ("wall", "cpu"):
            x = D[clock]
            w(f"| {clock} | {pm(x['paired_ratio'], x['paired_ratio_se'], 3)} | {', '.join(f'{r:.3f}' for r in x['ratio_per_rep'])} "
              f"| {pm(x['ratio'], x['ratio_se'], 3)} |")
    return "\n".join(L) + "\n"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--optimis", default="target/release/optimis")
    ap.add_argument("--work", required=True)
    ap.add_argument("--out", default="docs/experiments/radii")
    ap.add_argument("--parts", default="A,B,C,D")
    ap.add_argument("--wide-radius", type=float, default=0.02)
    ap.add_argument("--radii", default="0.003,0.005,0.01")
    ap.add_argument("--iterations", type=int, default=100000)
    ap.add_argument("--wide-seeds", default="101-110")
    ap.add_argument("--direct-seeds", default="201-210")
    ap.add_argument("--long-seed", type=int, default=301)
    ap.add_argument("--long", default="0.003:1000000,0.005:1000000,0.01:1000000",
                    help="iterations of the long direct run per R′ (part B)")
    ap.add_argument("--target", type=float, default=1.0)
    ap.add_argument("--check-seed", type=int, default=401)
    ap.add_argument("--check-iterations", default="20000,20000,20000",
                    help="iterations of the direct runs at the plan's three points (part C)")
    ap.add_argument("--replicate-seeds", default="404-408",
                    help="further direct runs at the plan's best point (part C), beside every wide run's plan")
    ap.add_argument("--far-point", default="0.005:316227766:100",
                    help="R′:N_F:N_B of a further direct run (part C): the plans' predictions far from the runs' budget")
    ap.add_argument("--far-seed", type=int, default=409)
    ap.add_argument("--far-iterations", type=int, default=100000)
    ap.add_argument("--no-paper-direct", dest="paper_direct", action="store_false",
                    help="do not measure the speed-up over the paper's setup from part A's direct runs")
    ap.add_argument("--timing-seed", type=int, default=501)
    ap.add_argument("--timing-long", type=int, default=40000)
    ap.add_argument("--timing-short", type=int, default=2000)
    ap.add_argument("--timing-reps", type=int, default=3)
    ap.add_argument("--date", default="2026-12-06")
    ap.add_argument("--commit", default="a5aa4ff + the best_strategy_points field")
    a = ap.parse_args()
    a.radii = [float(x) for x in a.radii.split(",")]
    a.long_text = a.long
    a.long = {str(float(k)): int(v) for k, v in (x.split(":") for x in a.long.split(","))}
    a.check_iterations = [int(x) for x in a.check_iterations.split(",")]
    os.makedirs(a.work, exist_ok=True)
    os.makedirs(a.out, exist_ok=True)
    logf = open(os.path.join(a.work, "study.log"), "a")

    def log(msg):
        line = time.strftime("%H:%M:%S ") + msg
        print(line, file=logf, flush=True)

    a.log = log
    R = Runner(a.optimis, a.work, log)
    res_file = os.path.join(a.out, "radii_study.json")
    res = json.load(open(res_file)) if os.path.exists(res_file) else {}
    parts = a.parts.split(",")
    if "A" in parts or "B" in parts:
        res["A"] = part_a(a, R)
    if "B" in parts:
        res["B"] = part_b(a, R, res["A"]["quadrature_bias"])
    if "C" in parts:
        res["C"] = part_c(a, R)
    if "D" in parts:
        res["D"] = part_d(a)
    elif "D" in res:
        res["D"] = analyse_d(res["D"])
    res["meta"] = {"date": a.date, "binary": a.optimis, "commit": a.commit, "work": a.work}
    json.dump(res, open(res_file, "w"), indent=1)
    md_file = os.path.join(a.out, "summary.md")
    remarks = ""
    if os.path.exists(md_file):
        text = open(md_file).read()
        if "<!-- remarks -->" in text:
            remarks = text[text.index("<!-- remarks -->"):]
    text = summary_md(a, res, R.commands)
    open(md_file, "w").write(text + ("\n" + remarks if remarks else ""))
    log("summary written")


if __name__ == "__main__":
    main()
