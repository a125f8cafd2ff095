"""The server's JSON tables as pandas DataFrames.

Each function takes a document the server returned (a result, a history, a sweep table, a
comparison) and needs no connection, so that a document fetched once — or read from a file — can be
turned into a table without asking the server again. Missing figures (JSON ``null``) become ``NaN``
in numeric columns.
"""

from __future__ import annotations

import math
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence

import pandas as pd

#: The columns :func:`noise_table_frame` adds to the server's row fields.
PAPER_COLUMNS = ("paper_luminance", "paper_rms_percent", "paper_case")

#: The numeric members of a noise-table row (float columns, ``NaN`` where the JSON has ``null``).
NOISE_NUMBERS = (
    "luminance",
    "luminance_stderr",
    "rms_percent",
    "rms_percent_stderr",
    "lambda",
    "in_sample_luminance",
    "in_sample_luminance_stderr",
    "in_sample_rms_percent",
    "expected_luminance",
    "z",
)

#: The columns of :func:`weights_frame`, in order (any further member of a cell follows them).
WEIGHT_COLUMNS = (
    "cell",
    "r2_lo",
    "r2_hi",
    "r3_lo",
    "r3_hi",
    "phi_lo_rad",
    "phi_hi_rad",
    "w0",
    "w0_stderr",
    "w1",
    "w1_stderr",
    "w2",
    "w2_stderr",
    "samples",
    "status",
)

#: The columns of :func:`history_frame`.
HISTORY_COLUMNS = ("iterations", "strategy", "luminance", "luminance_stderr", "rms_percent")

#: The per-run figure columns of a comparison (``GET /v1/compare``), in the server's order.
COMPARE_FIGURES = (
    "luminance",
    "luminance_stderr",
    "rms_percent",
    "rms_percent_stderr",
    "luminance_ratio",
    "luminance_ratio_stderr",
    "luminance_difference",
    "luminance_difference_stderr",
    "z",
    "rms_ratio",
    "rms_ratio_stderr",
)


def _columns(rows: Iterable[Mapping[str, Any]], first: Sequence[str] = ()) -> List[str]:
    """The keys of `rows` in order of first appearance, after `first`."""
    seen = list(first)
    for row in rows:
        for key in row:
            if key not in seen:
                seen.append(key)
    return seen


def _frame(records: List[Dict[str, Any]], columns: Sequence[str]) -> pd.DataFrame:
    """A DataFrame of `records` with exactly `columns` (an empty one keeps them)."""
    if not records:
        return pd.DataFrame({c: pd.Series([], dtype=object) for c in columns})
    return pd.DataFrame.from_records(records, columns=list(columns))


def paper_figures(result: Mapping[str, Any]) -> Dict[str, Dict[str, Any]]:
    """The published figures that apply to a result, by strategy.

    ``result["references"]`` holds the published tables whose configuration the job has (the
    paper's Table 1 for the paper's scene, R, N_F and N_B; empty otherwise). Each strategy gets the
    row of the first table that has one: ``{"case", "luminance", "rms_percent", "reference"}``
    (luminance in the model's units; ``reference`` the table's id), as the server's noise CSV does.
    """
    figures: Dict[str, Dict[str, Any]] = {}
    for table in result.get("references") or []:
        for row in table.get("rows") or []:
            figures.setdefault(
                row["strategy"],
                {
                    "case": row.get("case"),
                    "luminance": row.get("luminance"),
                    "rms_percent": row.get("rms_percent"),
                    "reference": table.get("id"),
                },
            )
    return figures


def noise_table_frame(result: Mapping[str, Any]) -> pd.DataFrame:
    """A result's noise table: one row per strategy, in the server's order.

    The columns are the JSON row's fields (``strategy``, ``luminance``, ``luminance_stderr``,
    ``rms_percent``, ``rms_percent_stderr``, ``lambda``, ``in_sample``, ``respects_fixed``,
    ``heuristics``, ``z``, ``error``, …) followed by ``paper_luminance``, ``paper_rms_percent`` and
    ``paper_case`` — the published figures where a reference table applies to the job (see
    :func:`paper_figures`), else missing (``NaN``, ``<NA>`` for the case number).
    """
    rows = list(result.get("noise_table") or [])
    columns = [c for c in _columns(rows, ("strategy",)) if c not in PAPER_COLUMNS]
    paper = paper_figures(result)
    records = []
    for row in rows:
        record = dict(row)
        published = paper.get(row["strategy"], {})
        record["paper_luminance"] = published.get("luminance")
        record["paper_rms_percent"] = published.get("rms_percent")
        record["paper_case"] = published.get("case")
        records.append(record)
    frame = _frame(records, columns + list(PAPER_COLUMNS))
    for column in NOISE_NUMBERS + ("paper_luminance", "paper_rms_percent"):
        if column in frame.columns:
            frame[column] = pd.to_numeric(frame[column], errors="coerce").astype("float64")
    frame["paper_case"] = pd.array([r["paper_case"] for r in records], dtype="Int64")
    return frame


def weights_frame(cells: Sequence[Mapping[str, Any]]) -> pd.DataFrame:
    """A weights table (a result's ``weights``): one row per cell, in the document's order.

    Each bin ``[lo, hi]`` is flattened into ``r2_lo``/``r2_hi``, ``r3_lo``/``r3_hi`` and
    ``phi_lo_rad``/``phi_hi_rad``; an open upper bound (the tail cell, ``null`` in JSON) is
    ``NaN``, as in the server's CSV. Then ``w0``, ``w1``, ``w2``, their ``_stderr`` (``NaN`` where a
    cell has no data standard error, e.g. ``smoothed``), ``samples`` and ``status``; ``cell`` is the
    cell's index. Empty (with these columns) when the recommendation is a per-path strategy.
    """
    records = []
    for index, cell in enumerate(cells):
        record: Dict[str, Any] = {"cell": index}
        for name, unit in (("r2", ""), ("r3", ""), ("phi", "_rad")):
            bounds = list(cell.get(name) or [None, None]) + [None, None]
            record[f"{name}_lo{unit}"], record[f"{name}_hi{unit}"] = bounds[0], bounds[1]
        for key, value in cell.items():
            if key not in ("r2", "r3", "phi"):
                record[key] = value
        records.append(record)
    frame = _frame(records, _columns(records, WEIGHT_COLUMNS))
    if records:
        for column in WEIGHT_COLUMNS[1:-2]:
            frame[column] = pd.to_numeric(frame[column], errors="coerce").astype("float64")
    return frame


def history_frame(history: Mapping[str, Any]) -> pd.DataFrame:
    """A job's history (``GET /v1/jobs/{id}/history``) in long format.

    One row per checkpoint and strategy, oldest first: ``iterations``, ``strategy``,
    ``luminance`` (model units), ``luminance_stderr`` = abs(L)·RMS/√M (as the server's CSV and the
    dashboard's band) and ``rms_percent`` (and any further member the server adds).
    """
    records = []
    for point in history.get("points") or []:
        outer = {k: v for k, v in point.items() if k != "strategies"}
        for figures in point.get("strategies") or []:
            record = {**outer, **figures}
            lum, rms, m = record.get("luminance"), record.get("rms_percent"), outer.get("iterations") or 0
            ok = lum is not None and rms is not None and m > 0
            record["luminance_stderr"] = abs(lum) * rms / 100.0 / math.sqrt(m) if ok else None
            records.append(record)
    return _frame(records, _columns(records, HISTORY_COLUMNS))


def sweep_table_frame(table: Mapping[str, Any]) -> pd.DataFrame:
    """A sweep's table (``GET /v1/sweeps/{id}/table``): one row per point and strategy.

    The columns are those of the server's CSV: ``point``, one per swept field (named by its path,
    e.g. ``merge_radius``, ``scene.l3``; a field that is already a column, such as ``light_paths``,
    is not repeated), then ``source``, ``light_paths``, ``camera_paths``, ``iterations``,
    ``partial``, ``strategy``, ``luminance``, ``luminance_stderr``, ``rms_percent``,
    ``rms_percent_stderr``, ``respects_fixed``, ``recommended`` and ``supported`` (false for a
    predicted figure its run does not support).
    """
    rows = list(table.get("rows") or [])
    own = [c for c in _columns(rows) if c not in ("point", "values")]
    swept = [f for f in table.get("fields") or [] if f not in own and f != "point"]
    records = []
    for row in rows:
        values = row.get("values") or {}
        record: Dict[str, Any] = {"point": row.get("point")}
        record.update({field: values.get(field) for field in swept})
        record.update({k: v for k, v in row.items() if k not in ("point", "values")})
        # docs/csv.md's name, which the JSON row has used since 0.1 (a server before it said
        # iterations_done).
        if "iterations_done" in record:
            record["iterations"] = record.pop("iterations_done")
        records.append(record)
    own = list(dict.fromkeys("iterations" if c == "iterations_done" else c for c in own))
    return _frame(records, ["point"] + swept + own)


def compare_frame(comparison: Mapping[str, Any], ids: Optional[Sequence[int]] = None) -> pd.DataFrame:
    """A comparison (``GET /v1/compare``) in long format: one row per strategy and run.

    Columns: ``strategy``, ``in_sample``, ``run`` (the run's label, ``job 3``), ``run_index`` (0
    for the baseline, the first run), ``job_id`` (from `ids`, in the order compared; missing when
    not given), ``iterations``, then every figure: ``luminance``, ``luminance_stderr``,
    ``rms_percent``, ``rms_percent_stderr`` and, against the baseline, ``luminance_ratio``,
    ``luminance_ratio_stderr``, ``luminance_difference``, ``luminance_difference_stderr``, ``z``,
    ``rms_ratio``, ``rms_ratio_stderr`` (missing on the baseline's own rows). ``frame.attrs`` keeps
    the server's ``runs`` (labels, fingerprints, iterations) and ``notes``.
    """
    runs = list(comparison.get("runs") or [])
    records = []
    for entry in comparison.get("strategies") or []:
        for index, figures in enumerate(entry.get("runs") or []):
            run = runs[index] if index < len(runs) else {}
            record: Dict[str, Any] = {
                "strategy": entry.get("strategy"),
                "in_sample": entry.get("in_sample"),
                "run": run.get("label"),
                "run_index": index,
                "job_id": ids[index] if ids is not None and index < len(ids) else None,
                "iterations": run.get("iterations"),
            }
            record.update(figures)
            records.append(record)
    first = ("strategy", "in_sample", "run", "run_index", "job_id", "iterations") + COMPARE_FIGURES
    frame = _frame(records, _columns(records, first))
    if records:
        for column in COMPARE_FIGURES:
            frame[column] = pd.to_numeric(frame[column], errors="coerce").astype("float64")
    frame.attrs["runs"] = runs
    frame.attrs["notes"] = list(comparison.get("notes") or [])
    return frame
