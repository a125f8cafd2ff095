"""Issue 44 beyond the paper's preset: a run at R = 0.02 with radii [0.005, 0.01] against direct
runs at each R', in two more scenes, over 10 seed pairs — the z of every per-path row's RMS, and the
calibration of the reported SEs (spread of the 10 wide runs' RMS over their mean SE).

    python3 docs/experiments/radii_scenes.py --optimis target/release/optimis --iterations 20000

Writes docs/experiments/radii/scenes.json and prints a Markdown table."""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
from pathlib import Path

SCENES = {
    "uniform-illumination": ["--preset", "uniform-illumination"],
    "beta 8°, l3 = 2": ["--set", "scene.beta_deg=8", "--set", "scene.l3=2"],
}
PER_PATH = ["plane1", "plane2", "plane3", "switch", "balance", "power", "correlation_aware",
            "balance_planes23", "power_planes23", "correlation_aware_planes23"]
RADII = [0.005, 0.01]


def run(binary: str, scene: list[str], iterations: int, seed: int, extra: list[str]) -> dict:
    cmd = [binary, "run", "--quiet", "--json", *scene, "--iterations", str(iterations), "--seed", str(seed),
           "--set", "noise_components=true", *extra]
    return json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--optimis", required=True)
    parser.add_argument("--iterations", type=int, default=20000)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--out", default="docs/experiments/radii/scenes.json")
    args = parser.parse_args()
    out = {}
    for name, scene in SCENES.items():
        pairs = {r: {s: [] for s in PER_PATH} for r in RADII}
        for i in range(args.seeds):
            wide = run(args.optimis, scene, args.iterations, 601 + i,
                       ["--set", "merge_radius=0.02", "--set", f"radii={json.dumps(RADII)}"])
            for r in RADII:
                direct = run(args.optimis, scene, args.iterations, 701 + i, ["--set", f"merge_radius={r}"])
                w_rows = {x["strategy"]: x for x in next(t for t in wide["radii"] if t["merge_radius"] == r)["rows"]}
                d_rows = {x["strategy"]: x for x in direct["noise_table"]}
                for s in PER_PATH:
                    w, d = w_rows[s], d_rows[s]
                    if None in (w["rms_percent"], w["rms_percent_stderr"], d["rms_percent"], d["rms_percent_stderr"]):
                        continue
                    pairs[r][s].append((w["rms_percent"], w["rms_percent_stderr"], d["rms_percent"], d["rms_percent_stderr"]))
        out[name] = {str(r): pairs[r] for r in RADII}
        print(f"\n### {name} ({args.seeds} seed pairs, {args.iterations} iterations)\n")
        print("| R′ | row | wide RMS % | direct RMS % | within 2.5 | mean z | wide spread / mean SE |")
        print("|---|---|---|---|---|---|---|")
        for r in RADII:
            for s in PER_PATH:
                p = pairs[r][s]
                if len(p) < 3:
                    print(f"| {r} | {s} | — | — | — | — | — |")
                    continue
                z = [(w - d) / (sw * sw + sd * sd) ** 0.5 for w, sw, d, sd in p]
                within = sum(abs(x) <= 2.5 for x in z)
                spread = statistics.stdev(w for w, *_ in p) / statistics.mean(sw for _, sw, *_ in p)
                wm = statistics.mean(w for w, *_ in p)
                dm = statistics.mean(d for *_, d, _ in p)
                print(f"| {r} | {s} | {wm:.2f} | {dm:.2f} | {within}/{len(p)} | {statistics.mean(z):+.2f} | {spread:.2f} |")
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
