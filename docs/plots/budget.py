#!/usr/bin/env python3
"""Plots the ray budget of `optimis budget --json` (docs/results.md §7, docs/model.md §12).

    optimis budget src-doc.json --target-rms 1 ... --json > budget.json
    python3 docs/plots/budget.py budget.json docs/figures/budget.png

Left: seconds to the target RMS against N_F, one line per N_B, for the re-fitted optimum
(optimal_cv, solid) and the paper's switch (dashed), with the paper's configuration and each
strategy's best budget marked. Right: the RMS every strategy reaches in the paper configuration's
time T against N_F/N_B (the plan's `fixed_time` curve: at each ratio the grid's best budget);
hollow markers flag ratios whose budget does not fit one iteration in T.

Python 3.11 and matplotlib; the output format follows the file's extension (.png or .svg).
"""

import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

LEFT = {"optimal_cv": "-", "switch": "--"}
MARKERS = "osD^v<>ph*"


def main(src: str, out: str) -> None:
    with open(src, encoding="utf-8") as f:
        plan = json.load(f)
    target = plan["target_rms_percent"]
    costs = plan["costs"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.8), layout="constrained")

    points = plan["points"]
    cameras = sorted({p["budget"]["camera_paths"] for p in points})
    colours = {nb: plt.cm.viridis(i / max(1, len(cameras) - 1)) for i, nb in enumerate(cameras)}
    for strategy, style in LEFT.items():
        mine = [p for p in points if p["strategy"] == strategy]
        for nb in cameras:
            line = sorted((p for p in mine if p["budget"]["camera_paths"] == nb), key=lambda p: p["budget"]["light_paths"])
            if not line:
                continue
            left.plot(
                [p["budget"]["light_paths"] for p in line],
                [p["seconds_to_target"] for p in line],
                style,
                color=colours[nb],
                marker=".",
            )
        best = next((b for b in plan["best"] if b["strategy"] == strategy), None)
        if best:
            left.plot(
                best["budget"]["light_paths"],
                best["seconds_to_target"],
                "o",
                ms=11,
                mfc="none",
                mec="red" if strategy == "optimal_cv" else "darkorange",
                mew=2,
                label=f"best {strategy}: ({best['budget']['light_paths']:.0e}, {best['budget']['camera_paths']}),"
                f" {best['seconds_to_target']:.3g} s",
            )
    paper = plan.get("paper")
    if paper:
        left.plot(
            paper["budget"]["light_paths"],
            paper["seconds_to_target"],
            "*",
            ms=15,
            color="black",
            label=f"paper: switch at (1e7, 100), {paper['seconds_to_target']:.3g} s",
        )
    left.set(
        xscale="log",
        yscale="log",
        xlabel="$N_F$ (light paths per iteration)",
        ylabel=f"seconds to {target:g}% RMS",
        title=f"Time to {target:g}% RMS, P = {costs['pixels']:.0e}",
    )
    left.grid(True, which="major", alpha=0.3)
    # One entry per N_B colour and per strategy's line style rather than one per line.
    keys = [Line2D([], [], color=colours[nb], label=f"$N_B$ = {nb}") for nb in cameras]
    keys += [Line2D([], [], color="grey", ls=style, label=strategy) for strategy, style in LEFT.items()]
    marked, labels = left.get_legend_handles_labels()
    left.legend(handles=keys + marked, labels=[k.get_label() for k in keys] + labels, fontsize=7, loc="lower left")

    fixed = plan.get("fixed_time")
    if fixed:
        curve = fixed["curve"]
        strategies = list(dict.fromkeys(c["strategy"] for c in curve))
        for i, strategy in enumerate(strategies):
            mine = sorted((c for c in curve if c["strategy"] == strategy), key=lambda c: c["ratio"])
            x = [c["ratio"] for c in mine]
            y = [c["rms_percent"] for c in mine]
            (line,) = right.plot(x, y, "-", marker=MARKERS[i % len(MARKERS)], ms=4, label=strategy)
            short = [c for c in mine if c["iterations"] < 1]
            if short:
                right.plot(
                    [c["ratio"] for c in short],
                    [c["rms_percent"] for c in short],
                    "o",
                    ms=8,
                    mfc="none",
                    mec=line.get_color(),
                )
        if paper:
            ratio = paper["budget"]["light_paths"] / paper["budget"]["camera_paths"]
            right.plot(ratio, target, "*", ms=15, color="black", label="paper: switch at (1e7, 100)")
        right.axhline(target, color="black", lw=0.8, ls=":")
        right.set(
            xscale="log",
            yscale="log",
            xlabel="$N_F / N_B$ (best budget on the grid at each ratio)",
            ylabel="RMS % after T",
            title=f"RMS after T = {fixed['seconds']:.3g} s (the paper's time to {target:g}%)",
        )
        right.grid(True, which="both", alpha=0.3)
        right.legend(fontsize=7, loc="upper right")

    fig.suptitle(
        f"t = t_F N_F + t_B N_B P + t_0: t_F = {costs['light_path']:.3g} s, t_B = {costs['camera_path']:.3g} s,"
        f" t_0 = {costs['iteration']:.3g} s",
        fontsize=9,
    )
    fig.savefig(out, dpi=90)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: budget.py BUDGET.json OUT.png|OUT.svg")
    main(sys.argv[1], sys.argv[2])
