#!/usr/bin/env python3
"""Reproduce Table 1 and Fig. 2 of the paper with an optimis server:
S. V. Ershov, A. G. Voloboy, D. D. Zhdanov, A. D. Zhdanov, V. A. Frolov, "Direct calculation of the optimal weight for MIS", GraphiCon 2020 (CEUR Workshop Proceedings).

Submits the paper's run (preset ``paper-table1``: three planes, β = 3°, the bright
spot a = 0.02, R = 0.003, N_F = 10^7, N_B = 100) to a running ``optimis serve``,
waits for it to finish, prints the noise table (the paper's Table 1) with our
standard errors and each row's z against its expected luminance at R beside the
paper's figures, marks the recommended row and says why (with the gain over the
best per-path strategy), and saves w1 against r3 (the paper's Fig. 2) as a PNG.

Fig. 2 follows the recommendation: the recommended row's weights table when it has
one (``optimal_stacked``'s is a correction on top of β·heuristics); when a per-path
strategy is recommended (no table), the table optimum at ``optimal_cv``'s λ. Cells
without a data standard error (``smoothed``: the gradient penalty set them) are
drawn as open markers without error bars.

It talks to the server through the ``optimis_client`` package (``clients/python``:
submit, wait with a long-poll, results, RFC 9457 problems raised as exceptions).
Run it from the repository's root (Python 3.9+; the package, with ``requests`` and
``pandas``, and ``matplotlib``)::

    python3 -m venv .venv && .venv/bin/pip install -r examples/python/requirements.txt ./clients/python
    optimis serve &                      # or: cargo run --release -- serve &
    .venv/bin/python examples/python/paper_table1.py --url http://127.0.0.1:8080 \\
        --iterations 10000 --seed 1 --out fig2.png --json table1.json

Options: ``--timeout`` bounds the whole wait (the job is cancelled when it runs
out); ``--weights-lambda 0`` draws the paper's own in-sample λ = 0 table optimum in
Fig. 2 instead. When the server requires a token, put it in the ``OPTIMIS_TOKEN``
environment variable (never on the command line, where ``ps`` shows it).

Exit status: 0 on success; 1 when the server refuses the job or the job fails (the
server's RFC 9457 problem detail is printed on stderr), when it is unreachable, or
when the timeout runs out (the job is then cancelled); 130 on Ctrl-C (likewise).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import textwrap
import time
from typing import Any, Dict, List, Optional

from optimis_client import Client, OptimisError, WaitTimeout, paper_figures


def published_rows(result: Dict[str, Any]) -> Dict[str, Dict[str, Any]]:
    """The paper's Table 1 rows that apply to this job, by strategy, as the server attaches them
    to the result (``references``: the repository's references/*.json, also GET /v1/references);
    empty when the job's configuration is not the paper's."""
    return {
        strategy: {
            "case": figures["case"],
            "luminance_1e5": figures["luminance"] * 1e5,
            "rms_percent": figures["rms_percent"],
        }
        for strategy, figures in paper_figures(result).items()
    }


def cancel_quietly(client: Client, job_id: int) -> None:
    """Best effort: stop a job we no longer wait for, so that it does not hold the server."""
    try:
        client.cancel(job_id)
    except OptimisError:
        pass


def wait_for(client: Client, job: Dict[str, Any], deadline: float, poll: float) -> Dict[str, Any]:
    """Wait until the job has succeeded (``Client.wait``: a long-poll that answers as soon as the
    job ends), reporting progress on stderr; the job is cancelled when the deadline passes or on
    Ctrl-C. Raises ``JobFailed`` when it failed or was cancelled.

    On a terminal the progress line is rewritten in place (every `poll` seconds at most); in a log
    (CI) one line is written per change of state.
    """
    job_id = job["id"]
    live = sys.stderr.isatty()
    last_state: List[Optional[str]] = [None]

    def report(current: Dict[str, Any]) -> None:
        progress = current.get("progress") or {}
        line = (f"job {job_id}: {current['state']:<9} {progress.get('iterations_done', 0)}"
                f"/{progress.get('iterations_total', 0)} iterations")
        if live:
            print(f"\r{line}", end="", file=sys.stderr, flush=True)
        elif current["state"] != last_state[0]:
            print(line, file=sys.stderr, flush=True)
        last_state[0] = current["state"]

    try:
        return client.wait(job_id, timeout=max(0.0, deadline - time.monotonic()), progress=report, poll=poll)
    except WaitTimeout as err:
        cancel_quietly(client, job_id)
        raise OptimisError(f"job {job_id} still {err.state} when the timeout ran out (cancelled it)") from err
    except KeyboardInterrupt:
        cancel_quietly(client, job_id)
        raise
    finally:
        if live:
            print(file=sys.stderr)


def fmt(value: Optional[float], digits: int, width: int) -> str:
    """A right-aligned number, or a dash for a missing one."""
    if value is None or not math.isfinite(value):
        return "—".rjust(width)
    return f"{value:{width}.{digits}f}"


def scaled(value: Optional[float]) -> Optional[float]:
    """Luminance in units of 10^-5, as the paper and the CLI print it."""
    return None if value is None else value * 1e5


def fmt_beta(heuristic: Dict[str, Any], named: bool = True) -> str:
    """One stacked heuristic's β ± SE, e.g. ``switch -0.126 ± 0.015`` (without the name: ``-0.126 ± 0.015``)."""
    stderr = heuristic.get("beta_stderr")
    text = f"{heuristic['beta']:+.3f}" + (f" ± {stderr:.3f}" if stderr is not None else "")
    return f"{heuristic['strategy']} {text}" if named else text


def wrap_items(head: str, items: List[str], width: int) -> List[str]:
    """``head`` and the items joined by ", ", broken into lines of at most `width` between items only."""
    lines = [head]
    for i, item in enumerate(items):
        piece = item + ("," if i < len(items) - 1 else "")
        if len(lines[-1]) + 1 + len(piece) > width and lines[-1].strip() != head.strip():
            lines.append(piece)
        else:
            lines[-1] += " " + piece
    return lines


def is_per_path(recommended: Optional[Dict[str, Any]]) -> bool:
    """Whether the recommendation is a per-path strategy (no λ, no weights table)."""
    return recommended is not None and recommended.get("lambda") is None


def table_rows(result: Dict[str, Any]) -> List[Dict[str, Any]]:
    """The noise table as printed: our figures, the flags and the paper's figures."""
    recommended = (result.get("recommended") or {}).get("strategy")
    published = published_rows(result)
    rows = []
    for row in result["noise_table"]:
        paper = published.get(row["strategy"], {})
        rows.append({
            "strategy": row["strategy"],
            "luminance_1e5": scaled(row.get("luminance")),
            "luminance_stderr_1e5": scaled(row.get("luminance_stderr")),
            # The expectation at the job's R by quadrature (per-path rows) and the row's z against it.
            "expected_luminance_1e5": scaled(row.get("expected_luminance")),
            "z": row.get("z"),
            "rms_percent": row.get("rms_percent"),
            "rms_percent_stderr": row.get("rms_percent_stderr"),
            "lambda": row.get("lambda"),
            # Fitted rows with heuristics stacked on the table: per-path weights = table + Σ β·heuristic.
            "heuristics": [dict(h) for h in row.get("heuristics") or []],
            "unstable": bool(row.get("unstable")),
            "in_sample": bool(row.get("in_sample")),
            "respects_fixed": bool(row.get("respects_fixed", True)),
            "recommended": row["strategy"] == recommended,
            "error": row.get("error"),
            "paper_case": paper.get("case"),
            "paper_luminance_1e5": paper.get("luminance_1e5"),
            "paper_rms_percent": paper.get("rms_percent"),
        })
    return rows


def print_table(rows: List[Dict[str, Any]], result: Dict[str, Any], job: Dict[str, Any]) -> None:
    spec = job["spec"]
    print(f"Table 1 — job {job['id']}: {result['iterations']} iterations, seed {spec.get('seed')}, "
          f"N_F = {spec.get('light_paths')}, N_B = {spec.get('camera_paths')}, R = {spec.get('merge_radius')}")
    reference = scaled(result.get("reference_luminance"))
    if reference is not None:
        print(f"reference (quadrature, R → 0) L·10⁵ = {reference:.4f}")
    print()
    width = max([18] + [len(row["strategy"]) for row in rows])
    print(f"{'strategy':<{width}} {'L·10⁵':>9} {'± SE':>8} {'z':>6} {'RMS %':>8} {'± SE':>6}   "
          f"{'paper L·10⁵':>11} {'RMS %':>6}  note")
    for row in rows:
        notes = []
        if row["recommended"]:
            notes.append("<- recommended")
        if row["in_sample"]:
            notes.append("in-sample (optimistic)")
        if row["lambda"] is not None:
            notes.append(f"λ = {row['lambda']:g}")
            if not row["in_sample"]:
                notes.append(f"{result.get('folds', 'K')}-fold cross-fitted")
        if len(row["heuristics"]) == 1:
            notes.append(f"β = {fmt_beta(row['heuristics'][0], named=False)}")
        if row["unstable"]:
            notes.append("unstable fit")
        if not row["respects_fixed"]:
            notes.append("outside the fixed weights")
        if row["error"]:
            notes.append(f"error: {row['error']}")
        paper = ""
        if row["paper_case"] is not None:
            paper = f"{row['paper_luminance_1e5']:11.3f} {row['paper_rms_percent']:6.0f}"
        print(f"{row['strategy']:<{width}} {fmt(row['luminance_1e5'], 4, 9)} {fmt(row['luminance_stderr_1e5'], 4, 8)} "
              f"{fmt(row['z'], 2, 6)} {fmt(row['rms_percent'], 1, 8)} {fmt(row['rms_percent_stderr'], 1, 6)}   "
              f"{paper:<18}  {', '.join(notes)}".rstrip())
        if len(row["heuristics"]) > 1:
            # A stacked row's β, one line under it (indented, so that it is not read as a row).
            lines = wrap_items("    β:", [fmt_beta(h) for h in row["heuristics"]], width=100)
            print("\n       ".join(lines))
    print()
    print("SE: standard error. z = (L − E[L])/SE, E[L] the row's expected luminance at the job's R by quadrature")
    print("(per-path rows; a fitted row has none: its weights follow these iterations). optimal is the paper's")
    print("procedure (fitted and scored on the same iterations, so its L is biased and its RMS too small); the")
    print("other fitted rows are cross-fitted. β: per-path weights = table + Σ β·heuristic.")
    recommended = result.get("recommended")
    if recommended:
        if is_per_path(recommended):
            kind = "per-path strategy, no weights table"
        else:
            kind = f"λ = {recommended['lambda']:g}"
            if recommended.get("heuristics"):
                kind += f", table + β·({', '.join(h['strategy'] for h in recommended['heuristics'])})"
        print(f"recommended: {recommended['strategy']} ({kind})")
        if recommended.get("reason"):
            print(textwrap.fill(f"because {recommended['reason']}", width=100, initial_indent="  ",
                                subsequent_indent="  ", break_on_hyphens=False))
    elif result.get("solve_error"):
        print(f"recommended: none ({result['solve_error']})")
    gain = result.get("gain")
    if gain and gain.get("value") is not None:
        stderr = gain.get("stderr")
        # Two significant digits of the SE (at least two decimals): 1.37 ± 0.11, 1.0035 ± 0.0013.
        digits = 2 if not stderr or stderr >= 0.01 else min(6, 1 - math.floor(math.log10(stderr)))
        spread = f" ± {stderr:.{digits}f}" if stderr is not None else ""
        print(f"gain: Var({gain.get('versus')}) / Var({gain.get('strategy')}) = {gain['value']:.{digits}f}{spread}")
    for warning in result.get("warnings") or []:
        print(f"warning [{warning.get('code')}]: {warning.get('message')}")


def figure_table(client: Client, job: Dict[str, Any], result: Dict[str, Any],
                 weights_lambda: Optional[float]) -> Dict[str, Any]:
    """Which weights table Fig. 2 draws, fetching it when it is not the result's own.

    The in-sample table optimum at --weights-lambda when asked for; else the recommended row's
    table when it has one; else (a per-path strategy is recommended: `weights` is empty) the table
    optimum at optimal_cv's λ, from ``?lambda=``. Returns what was drawn (`source`, `strategy`,
    `lambda`, `title`, …) with the cells in `weights`.
    """
    recommended = result.get("recommended")
    if recommended is None:
        said = f"none ({result.get('solve_error') or 'no row could be computed'})"
    elif is_per_path(recommended):
        said = f"{recommended['strategy']} (per-path, no table)"
    else:
        said = f"{recommended['strategy']} (λ = {recommended['lambda']:g})"
    figure: Dict[str, Any] = {"recommended": (recommended or {}).get("strategy"), "heuristics": []}
    if weights_lambda is not None:
        document = client.result(job["id"], lam=weights_lambda)
        figure["source"], figure["strategy"], figure["lambda"] = "lambda", "optimal", weights_lambda
        figure["title"] = f"in-sample table optimum (optimal, λ = {weights_lambda:g}); recommended: {said}"
    elif result.get("weights"):
        document = result
        fit = result.get("weights_fit") or {}
        figure["source"], figure["strategy"], figure["lambda"] = "recommended", fit.get("strategy"), fit.get("lambda")
        figure["heuristics"] = list((recommended or {}).get("heuristics") or [])
        figure["title"] = f"recommended: {fit.get('strategy')}, λ = {fit.get('lambda', float('nan')):g}"
    else:
        cv = next((row for row in result["noise_table"] if row["strategy"] == "optimal_cv"), {})
        figure["source"], figure["strategy"], figure["lambda"] = "lambda", "optimal_cv", cv.get("lambda")
        if cv.get("lambda") is None:
            figure.update(source="none", cells=0, cells_without_stderr=0, weights=[],
                          title=f"no table; recommended: {said}",
                          message=f"no weights table to draw: optimal_cv has no λ ({cv.get('error') or 'no row'})")
            return figure
        document = client.result(job["id"], lam=cv["lambda"])
        figure["title"] = f"table optimum (optimal_cv, λ = {cv['lambda']:g}); recommended: {said}"
    cells = document.get("weights") or []
    figure["cells"] = len(cells)
    figure["cells_without_stderr"] = sum(1 for c in cells if no_data_se(c))
    if not cells:
        figure["message"] = f"no weights table to draw: {document.get('solve_error') or 'the table is empty'}"
    figure["weights"] = cells
    return figure


def no_data_se(cell: Dict[str, Any]) -> bool:
    """A cell whose w1 has no data standard error: set by the penalty (smoothed), empty, …"""
    return cell.get("status") == "smoothed" or cell.get("w1_stderr") is None


SMOOTHED_LABEL = "smoothed (set by the penalty): no data SE"
# Open markers for the cells without a data SE, by status: (marker, legend entry).
NO_SE_STYLE = {
    "smoothed": ("o", SMOOTHED_LABEL),
    "empty": ("s", "empty (copied from the nearest fitted cell): no data SE"),
    "uninformative": ("D", "uninformative (treated as empty): no data SE"),
}


def save_fig2(figure: Dict[str, Any], job: Dict[str, Any], iterations: int, path: str) -> None:
    """Fig. 2: a table's w1 against r3, one panel per r2 bin, ±1 SE bars, r3 = a marked.

    Cells without a data standard error (smoothed by the penalty, or any null w1_stderr) are
    drawn as open markers without bars.
    """
    import matplotlib

    matplotlib.use("Agg")  # no display needed
    import matplotlib.pyplot as plt

    # Group the cells by r2 bin (one panel each) and φ bin (one series each), leaving out the
    # r3 tail cell (its upper edge is null: it reaches to infinity).
    panels: Dict[tuple, Dict[tuple, List[Dict[str, Any]]]] = {}
    for cell in figure.get("weights") or []:
        if cell["r3"][1] is None:
            continue
        panels.setdefault(tuple(cell["r2"]), {}).setdefault(tuple(cell["phi"]), []).append(cell)

    illumination = job["spec"].get("scene", {}).get("illumination", {})
    spot_radius = illumination.get("a") if illumination.get("kind", "spot") == "spot" else None
    heuristics = figure.get("heuristics") or []
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]

    count = max(1, len(panels))
    fig, axes = plt.subplots(1, count, figsize=(max(5.5 * count, 9.0), 4.6), sharey=True, squeeze=False)
    if not panels:
        ax = axes[0][0]
        ax.text(0.5, 0.5, figure.get("message", "no weights table"), transform=ax.transAxes, ha="center",
                va="center", wrap=True)
        ax.set_axis_off()
    for ax, (r2, series) in zip(axes[0], sorted(panels.items(), key=lambda item: item[0][0])):
        outside = 0
        labelled = set()
        for index, (phi, cells) in enumerate(sorted(series.items())):
            colour = colours[index % len(colours)]
            cells.sort(key=lambda c: c["r3"][0])
            prefix = "" if len(series) == 1 else f"φ ∈ [{phi[0]:.2f}, {phi[1]:.2f}): "
            measured = [c for c in cells if not no_data_se(c)]
            if measured:
                ax.errorbar([(c["r3"][0] + c["r3"][1]) / 2 for c in measured], [c["w1"] for c in measured],
                            xerr=[(c["r3"][1] - c["r3"][0]) / 2 for c in measured],
                            yerr=[c["w1_stderr"] for c in measured], fmt="o", ms=4, capsize=2, color=colour,
                            label=f"{prefix}w1 ± 1 SE")
            # Cells without a data SE: open markers, no bars (their spread would be their neighbours').
            by_status: Dict[str, List[Dict[str, Any]]] = {}
            for c in cells:
                if no_data_se(c):
                    by_status.setdefault(c.get("status") or "unknown", []).append(c)
            for status, group in sorted(by_status.items()):
                marker, label = NO_SE_STYLE.get(status, ("v", f"{status}: no data SE"))
                label = prefix + label
                ax.plot([(c["r3"][0] + c["r3"][1]) / 2 for c in group], [c["w1"] for c in group], marker, ms=5,
                        mfc="white", mec=colour, mew=1.2, label=None if label in labelled else label)
                labelled.add(label)
            outside += sum(1 for c in cells if not -1.0 <= c["w1"] <= 2.0)
        if spot_radius is not None:
            ax.axvline(spot_radius, color="grey", ls="--", lw=1)
            ax.annotate(f" r3 = a = {spot_radius:g}", (spot_radius, 0.03), xycoords=("data", "axes fraction"),
                        ha="left", fontsize=8, color="grey")
            if not heuristics:
                # The paper's case 4 (switch) for comparison: w1 = 1 inside the spot, 0 outside. Not
                # beside a stacked table, which is a correction on top of β·heuristics.
                r3_max = max(c["r3"][1] for cells in series.values() for c in cells)
                ax.plot([0, spot_radius, spot_radius, r3_max], [1, 1, 0, 0], color="grey", lw=0.8, alpha=0.6,
                        label="switch (case 4)")
        if outside:
            # The in-sample λ = 0 fit is ragged; keep the axes readable and say what is off the chart.
            ax.set_ylim(-1.0, 2.0)
            ax.text(0.98, 0.02, f"{outside} cell(s) outside [-1, 2]", transform=ax.transAxes, ha="right", fontsize=8)
        hi = "∞" if r2[1] is None else f"{r2[1]:g}"
        ax.set_title(f"r2 ∈ [{r2[0]:g}, {hi})")
        ax.set_xlabel("r3")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    if panels:
        axes[0][0].set_ylabel("table w1 (per path: + Σ β·w1,h)" if heuristics
                              else "w1 (w0 = 0, w2 = 1 − w1)")
    title = f"Fig. 2 — w1(r3): {figure['title']}\njob {job['id']}, {iterations} iterations"
    if heuristics:
        title += "\n" + "\n".join(wrap_items("per path: w1 = table w1 + Σ β·w1 of the heuristics, β:",
                                             [fmt_beta(h) for h in heuristics], width=max(80, 65 * count)))
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--url", default="http://127.0.0.1:8080", help="server base URL")
    parser.add_argument("--iterations", type=int, default=10000, help="iterations (paper: 10^4)")
    parser.add_argument("--seed", type=int, default=1, help="random seed")
    parser.add_argument("--out", default="fig2.png", help="where to save Fig. 2 (PNG)")
    parser.add_argument("--json", dest="json_path", help="also write the printed table rows to this JSON file")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds to wait for the job in all")
    parser.add_argument("--poll", type=float, default=0.5,
                        help="seconds between progress reports (the wait ends as soon as the job does)")
    parser.add_argument("--weights-lambda", type=float, default=None,
                        help="draw the in-sample table optimum at this λ in Fig. 2 (0: the paper's) "
                             "instead of the recommended weights")
    args = parser.parse_args(argv)

    # The bearer token, when the server requires one, comes from $OPTIMIS_TOKEN.
    client = Client(args.url, timeout=30.0)
    deadline = time.monotonic() + args.timeout
    job_document = {"preset": "paper-table1", "iterations": args.iterations, "seed": args.seed}

    try:
        job = client.submit(job_document)
        print(f"submitted job {job['id']} to {args.url}", file=sys.stderr)
        # Raises JobFailed ("job N failed: why") unless it succeeded.
        job = wait_for(client, job, deadline, args.poll)
        result = client.result(job["id"])
        # Fig. 2's table: the recommended one, the table optimum at optimal_cv's λ when a per-path
        # strategy is recommended, or the in-sample fit at the λ asked for.
        figure = figure_table(client, job, result, args.weights_lambda)
    except OptimisError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted (the job was cancelled)", file=sys.stderr)
        return 130

    rows = table_rows(result)
    print_table(rows, result, job)

    save_fig2(figure, job, result["iterations"], args.out)
    print(f"\nFig. 2 ({figure['title']}; {figure['cells_without_stderr']} of {figure['cells']} cells "
          f"without a data SE) saved to {args.out}")

    if args.json_path:
        document = {
            "job_id": job["id"],
            "url": args.url,
            "iterations": result["iterations"],
            "seed": job["spec"].get("seed"),
            "recommended": result.get("recommended"),
            "gain": result.get("gain"),
            "reference_luminance_1e5": scaled(result.get("reference_luminance")),
            "figure": args.out,
            "figure_table": {k: v for k, v in figure.items() if k != "weights"},
            "rows": rows,
        }
        with open(args.json_path, "w", encoding="utf-8") as handle:
            json.dump(document, handle, indent=2)
            handle.write("\n")
        print(f"table written to {args.json_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
