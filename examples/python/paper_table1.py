#!/usr/bin/env python3
"""Reproduce Table 1 and Fig. 2 of Ershov et al. (2020) with an optimis server.

Submits the paper's run (preset ``paper-table1``: three planes, β = 3°, the bright
spot a = 0.02, R = 0.003, N_F = 10^7, N_B = 100) to a running ``optimis serve``,
waits for it to finish, prints the noise table (the paper's Table 1) with our
standard errors beside the paper's figures, and saves the optimal weight w1 against
r3 (the paper's Fig. 2) as a PNG.

Run it (Python 3.9+; ``requests`` and ``matplotlib``)::

    python3 -m venv .venv && .venv/bin/pip install -r examples/python/requirements.txt
    optimis serve &                      # or: cargo run --release -- serve &
    .venv/bin/python examples/python/paper_table1.py --url http://127.0.0.1:8080 \\
        --iterations 10000 --seed 1 --out fig2.png --json table1.json

Options: ``--timeout`` bounds the whole wait (the job is cancelled when it runs
out); ``--weights-lambda 0`` draws the paper's own in-sample λ = 0 fit in Fig. 2
instead of the recommended, cross-validated weights. When the server requires a
token, put it in the ``OPTIMIS_TOKEN`` environment variable (never on the command
line, where ``ps`` shows it).

Exit status: 0 on success; 1 when the server refuses the job or the job fails (the
server's RFC 9457 problem detail is printed on stderr), when it is unreachable, or
when the timeout runs out (the job is then cancelled); 130 on Ctrl-C (likewise).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from typing import Any, Dict, List, Optional

import requests

# The paper's Table 1 (10^4 iterations, weights fitted on the same iterations):
# case number, L·10^5 and RMS % for the strategies that have a counterpart here.
# `optimal` is the paper's procedure (fitted and scored in-sample, λ = 0).
PAPER_TABLE1: Dict[str, Dict[str, float]] = {
    "plane1": {"case": 1, "luminance_1e5": 26.484, "rms_percent": 208.0},
    "plane2": {"case": 2, "luminance_1e5": 26.352, "rms_percent": 254.0},
    "plane3": {"case": 3, "luminance_1e5": 25.997, "rms_percent": 146.0},
    "switch": {"case": 4, "luminance_1e5": 26.352, "rms_percent": 61.0},
    "optimal": {"case": 5, "luminance_1e5": 25.961, "rms_percent": 54.0},
}

# Job states after which nothing changes any more.
FINAL_STATES = ("succeeded", "failed", "cancelled")


class ApiError(Exception):
    """A request failed; the message carries the server's problem detail when there is one."""


class Client:
    """A minimal optimis client: JSON in, JSON out, problem+json errors raised as ApiError."""

    def __init__(self, base_url: str, token: Optional[str], request_timeout: float) -> None:
        self.base_url = base_url.rstrip("/")
        self.request_timeout = request_timeout
        self.session = requests.Session()
        self.session.headers["Accept"] = "application/json"
        if token:
            self.session.headers["Authorization"] = f"Bearer {token}"

    def request(self, method: str, path: str, deadline: float, **kwargs: Any) -> requests.Response:
        """Send one request; wait and retry while the server answers 429/503 with Retry-After."""
        url = self.base_url + path
        while True:
            try:
                response = self.session.request(method, url, timeout=self.request_timeout, **kwargs)
            except requests.RequestException as err:
                raise ApiError(f"{method} {url}: {err}") from err
            retry_after = response.headers.get("Retry-After")
            if response.status_code in (429, 503) and retry_after is not None:
                try:
                    pause = float(retry_after)
                except ValueError:
                    pause = 1.0
                if time.monotonic() + pause < deadline:
                    time.sleep(pause)
                    continue
            if response.status_code >= 400:
                raise ApiError(describe_problem(method, url, response))
            return response

    def submit(self, job: Dict[str, Any], deadline: float) -> Dict[str, Any]:
        return self.request("POST", "/v1/jobs", deadline, json=job).json()

    def job(self, job_id: int, deadline: float) -> Dict[str, Any]:
        return self.request("GET", f"/v1/jobs/{job_id}", deadline).json()

    def result(self, job_id: int, deadline: float, weights_lambda: Optional[float] = None) -> Dict[str, Any]:
        params = {} if weights_lambda is None else {"lambda": weights_lambda}
        return self.request("GET", f"/v1/jobs/{job_id}/result", deadline, params=params).json()

    def cancel(self, job_id: int) -> None:
        """Best effort: stop a job we no longer wait for, so that it does not hold the server."""
        try:
            self.session.post(f"{self.base_url}/v1/jobs/{job_id}/cancel", timeout=self.request_timeout)
        except requests.RequestException:
            pass


def describe_problem(method: str, url: str, response: requests.Response) -> str:
    """One line out of an RFC 9457 problem document (or whatever the body is)."""
    try:
        problem = response.json()
    except ValueError:
        problem = None
    if isinstance(problem, dict) and "detail" in problem:
        text = f"{problem.get('title', 'error')} ({response.status_code}): {problem['detail']}"
        if problem.get("field"):
            text += f" [field: {problem['field']}]"
        return text
    body = response.text.strip()[:200]
    return f"{method} {url}: HTTP {response.status_code} {body}"


def wait_for(client: Client, job: Dict[str, Any], deadline: float, poll: float) -> Dict[str, Any]:
    """Poll the job until it reaches a final state, reporting progress on stderr.

    On a terminal the progress line is rewritten in place; in a log (CI) one line is written
    per change of state.
    """
    job_id = job["id"]
    live = sys.stderr.isatty()
    last_state = None
    try:
        while job["state"] not in FINAL_STATES:
            if time.monotonic() >= deadline:
                client.cancel(job_id)
                raise ApiError(f"job {job_id} still {job['state']} when the timeout ran out (cancelled it)")
            time.sleep(poll)
            job = client.job(job_id, deadline)
            progress = job.get("progress") or {}
            line = (f"job {job_id}: {job['state']:<9} {progress.get('iterations_done', 0)}"
                    f"/{progress.get('iterations_total', 0)} iterations")
            if live:
                print(f"\r{line}", end="", file=sys.stderr, flush=True)
            elif job["state"] != last_state:
                print(line, file=sys.stderr, flush=True)
            last_state = job["state"]
    except KeyboardInterrupt:
        client.cancel(job_id)
        raise
    finally:
        if live:
            print(file=sys.stderr)
    return job


def fmt(value: Optional[float], digits: int, width: int) -> str:
    """A right-aligned number, or a dash for a missing one."""
    if value is None or not math.isfinite(value):
        return "—".rjust(width)
    return f"{value:{width}.{digits}f}"


def scaled(value: Optional[float]) -> Optional[float]:
    """Luminance in units of 10^-5, as the paper and the CLI print it."""
    return None if value is None else value * 1e5


def table_rows(result: Dict[str, Any]) -> List[Dict[str, Any]]:
    """The noise table as printed: our figures, the flags and the paper's figures."""
    recommended = (result.get("recommended") or {}).get("strategy")
    rows = []
    for row in result["noise_table"]:
        paper = PAPER_TABLE1.get(row["strategy"], {})
        rows.append({
            "strategy": row["strategy"],
            "luminance_1e5": scaled(row.get("luminance")),
            "luminance_stderr_1e5": scaled(row.get("luminance_stderr")),
            "rms_percent": row.get("rms_percent"),
            "rms_percent_stderr": row.get("rms_percent_stderr"),
            "lambda": row.get("lambda"),
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
        print(f"reference (quadrature) L·10⁵ = {reference:.4f}")
    print()
    print(f"{'strategy':<18} {'L·10⁵':>9} {'± SE':>8} {'RMS %':>8} {'± SE':>6}   "
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
        if not row["respects_fixed"]:
            notes.append("outside the fixed weights")
        if row["error"]:
            notes.append(f"error: {row['error']}")
        paper = ""
        if row["paper_case"] is not None:
            paper = f"{row['paper_luminance_1e5']:11.3f} {row['paper_rms_percent']:6.0f}"
        print(f"{row['strategy']:<18} {fmt(row['luminance_1e5'], 4, 9)} {fmt(row['luminance_stderr_1e5'], 4, 8)} "
              f"{fmt(row['rms_percent'], 1, 8)} {fmt(row['rms_percent_stderr'], 1, 6)}   "
              f"{paper:<18}  {', '.join(notes)}")
    print()
    print("SE: standard error. optimal is the paper's procedure (fitted and scored on the same iterations,")
    print("so its L is biased and its RMS too small); optimal_holdout and optimal_cv are cross-fitted.")
    gain = result.get("gain")
    if gain and gain.get("value") is not None:
        stderr = gain.get("stderr")
        spread = f" ± {stderr:.2f}" if stderr is not None else ""
        print(f"gain: Var({gain.get('versus')}) / Var({gain.get('strategy')}) = {gain['value']:.2f}{spread}")
    for warning in result.get("warnings") or []:
        print(f"warning [{warning.get('code')}]: {warning.get('message')}")


def save_fig2(result: Dict[str, Any], job: Dict[str, Any], path: str, title_fit: str) -> None:
    """Fig. 2: the optimal w1 against r3, one panel per r2 bin, ±1 SE bars, r3 = a marked."""
    import matplotlib

    matplotlib.use("Agg")  # no display needed
    import matplotlib.pyplot as plt

    # Group the cells by r2 bin (one panel each) and φ bin (one series each), leaving out the
    # r3 tail cell (its upper edge is null: it reaches to infinity).
    panels: Dict[tuple, Dict[tuple, List[Dict[str, Any]]]] = {}
    for cell in result["weights"]:
        if cell["r3"][1] is None:
            continue
        panels.setdefault(tuple(cell["r2"]), {}).setdefault(tuple(cell["phi"]), []).append(cell)

    illumination = job["spec"].get("scene", {}).get("illumination", {})
    spot_radius = illumination.get("a") if illumination.get("kind", "spot") == "spot" else None

    fig, axes = plt.subplots(1, len(panels), figsize=(5.5 * len(panels), 4.2), sharey=True, squeeze=False)
    for ax, (r2, series) in zip(axes[0], sorted(panels.items(), key=lambda item: item[0][0])):
        outside = 0
        for phi, cells in series.items():
            cells.sort(key=lambda c: c["r3"][0])
            centre = [(c["r3"][0] + c["r3"][1]) / 2 for c in cells]
            half = [(c["r3"][1] - c["r3"][0]) / 2 for c in cells]
            w1 = [c["w1"] for c in cells]
            se = [c.get("w1_stderr") or 0.0 for c in cells]
            label = "w1 ± 1 SE" if len(series) == 1 else f"φ ∈ [{phi[0]:.2f}, {phi[1]:.2f})"
            bars = ax.errorbar(centre, w1, xerr=half, yerr=se, fmt="o", ms=4, capsize=2, label=label)
            # Cells whose weight is not fitted from their own data (smoothed, empty, uninformative).
            unfitted = [i for i, c in enumerate(cells) if c.get("status") not in ("fitted", "fixed")]
            if unfitted:
                ax.plot([centre[i] for i in unfitted], [w1[i] for i in unfitted], "o", ms=7, mfc="white",
                        mec=bars[0].get_color(), label="not fitted from its own data (status)")
            outside += sum(1 for w in w1 if not -1.0 <= w <= 2.0)
        if spot_radius is not None:
            ax.axvline(spot_radius, color="grey", ls="--", lw=1)
            ax.annotate(f" r3 = a = {spot_radius:g}", (spot_radius, 0.03), xycoords=("data", "axes fraction"),
                        ha="left", fontsize=8, color="grey")
            # The paper's case 4 (switch) for comparison: w1 = 1 inside the spot, 0 outside.
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
        ax.legend(fontsize=8, loc="upper right")
    axes[0][0].set_ylabel("w1 (w0 = 0, w2 = 1 − w1)")
    fig.suptitle(f"Fig. 2 — optimal w1(r3), {title_fit}, job {job['id']}, {result['iterations']} iterations")
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
    parser.add_argument("--poll", type=float, default=0.5, help="seconds between polls")
    parser.add_argument("--weights-lambda", type=float, default=None,
                        help="draw the in-sample fit at this λ in Fig. 2 (0: the paper's) "
                             "instead of the recommended weights")
    args = parser.parse_args(argv)

    client = Client(args.url, os.environ.get("OPTIMIS_TOKEN"), request_timeout=30.0)
    deadline = time.monotonic() + args.timeout
    job_document = {"preset": "paper-table1", "iterations": args.iterations, "seed": args.seed}

    try:
        job = client.submit(job_document, deadline)
        print(f"submitted job {job['id']} to {args.url}", file=sys.stderr)
        job = wait_for(client, job, deadline, args.poll)
        if job["state"] != "succeeded":
            raise ApiError(f"job {job['id']} {job['state']}: {job.get('error') or 'no reason given'}")
        result = client.result(job["id"], deadline)
        # Fig. 2's weights: the recommended ones, or the in-sample fit at the λ asked for.
        weights = result if args.weights_lambda is None else client.result(job["id"], deadline, args.weights_lambda)
    except ApiError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted (the job was cancelled)", file=sys.stderr)
        return 130

    rows = table_rows(result)
    print_table(rows, result, job)

    fit = weights.get("weights_fit") or {}
    title_fit = f"{fit.get('strategy', 'recommended')}, λ = {fit.get('lambda', float('nan')):g}"
    save_fig2(weights, job, args.out, title_fit)
    print(f"\nFig. 2 saved to {args.out}")

    if args.json_path:
        document = {
            "job_id": job["id"],
            "url": args.url,
            "iterations": result["iterations"],
            "seed": job["spec"].get("seed"),
            "recommended": result.get("recommended"),
            "reference_luminance_1e5": scaled(result.get("reference_luminance")),
            "figure": args.out,
            "rows": rows,
        }
        with open(args.json_path, "w", encoding="utf-8") as handle:
            json.dump(document, handle, indent=2)
            handle.write("\n")
        print(f"table written to {args.json_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
