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


#: The columns of :func:`error_plan_frame`, in order (any further member of a point follows them).
ERROR_PLAN_COLUMNS = (
    "strategy",
    "merge_radius",
    "own",
    "light_paths",
    "camera_paths",
    "rms_percent",
    "rms_percent_stderr",
    "bias_percent",
    "bias_percent_stderr",
    "iterations",
    "seconds_per_iteration",
    "seconds_to_target",
    "seconds_to_target_stderr",
    "supported",
    "respects_fixed",
    "best",
)

# The float columns of :func:`error_plan_frame` (NaN where the JSON has null).
_ERROR_PLAN_NUMBERS = (
    "merge_radius",
    "rms_percent",
    "rms_percent_stderr",
    "bias_percent",
    "bias_percent_stderr",
    "iterations",
    "seconds_per_iteration",
    "seconds_to_target",
    "seconds_to_target_stderr",
)

#: The columns of :func:`radii_frame`, in order (any further member of a row follows them).
RADII_COLUMNS = (
    "merge_radius",
    "own",
    "strategy",
    "recommended",
    "luminance",
    "luminance_stderr",
    "rms_percent",
    "rms_percent_stderr",
    "bias_percent",
    "bias_percent_stderr",
    "bias_source",
    "respects_fixed",
    "merges_plane1",
    "merges_plane2",
    "merges_plane3",
)

# The float columns of :func:`radii_frame` (NaN where the JSON has null).
_RADII_NUMBERS = (
    "merge_radius",
    "luminance",
    "luminance_stderr",
    "rms_percent",
    "rms_percent_stderr",
    "bias_percent",
    "bias_percent_stderr",
    "merges_plane1",
    "merges_plane2",
    "merges_plane3",
)


def _same_point(a: Mapping[str, Any], b: Optional[Mapping[str, Any]]) -> bool:
    """Whether two error points are the same (strategy, radius, budget)."""
    return b is not None and all(a.get(k) == b.get(k) for k in ("strategy", "merge_radius", "budget"))


def error_plan_frame(plan: Mapping[str, Any]) -> pd.DataFrame:
    """The plan to a target error (``POST /v1/jobs/{id}/budget`` with ``target_rmse``): its
    candidates, one row per (radius, strategy) that can reach the target — its fastest point — in
    the server's order (the points that keep the fixed weights first, then those the run supports,
    each by time to the target).

    `plan` is the budget call's answer (:meth:`Client.budget`) or its ``error_plan`` member; an
    answer without one (asked without ``target_rmse``) raises :class:`ValueError`.

    Columns: ``strategy``; ``merge_radius`` (R′, one of the radii the run tallied or its own R) and
    ``own`` (whether it is the run's own R); the budget ``light_paths`` (N_F) and ``camera_paths``
    (N_B); ``rms_percent`` (the predicted RMS% of one iteration there) and ``bias_percent`` (the
    strategy's bias at R′, % of L), each with its ``_stderr``; ``iterations`` to the target
    (max(1, σ²/(P² − b²))), ``seconds_per_iteration`` (merges included), ``seconds_to_target`` and
    its ``seconds_to_target_stderr``; ``supported`` (the run supports the prediction),
    ``respects_fixed`` (the strategy keeps the solver's fixed weights); ``best`` (true on the plan's
    fastest point, at most one row). Missing errors are ``NaN``.

    ``frame.attrs`` keeps the plan's other members: ``target_rmse_percent``, ``costs`` (``merge``:
    t_M), ``radii`` (ascending, the run's own R last), ``best``, ``at_own_radius`` and ``paper``
    (points as the JSON has them, or None), ``speedup_over_paper``, ``speedup_over_own_radius`` and
    their ``_stderr``, ``out_of_reach`` (the (strategy, radius) pairs whose bias alone reaches the
    target), ``progressive`` and ``notes``.
    """
    if "candidates" not in plan:
        inner = plan.get("error_plan")
        if not isinstance(inner, Mapping):
            raise ValueError("the budget plan has no error_plan: ask for one with target_rmse")
        plan = inner
    radii = list(plan.get("radii") or [])
    own = radii[-1] if radii else None
    best = plan.get("best")
    records = []
    for point in plan.get("candidates") or []:
        budget = point.get("budget") or {}
        record: Dict[str, Any] = {
            "strategy": point.get("strategy"),
            "merge_radius": point.get("merge_radius"),
            "own": own is not None and point.get("merge_radius") == own,
            "light_paths": budget.get("light_paths"),
            "camera_paths": budget.get("camera_paths"),
        }
        record.update({k: v for k, v in point.items() if k != "budget" and k not in record})
        record["best"] = _same_point(point, best)
        records.append(record)
    frame = _frame(records, _columns(records, ERROR_PLAN_COLUMNS))
    if records:
        for column in _ERROR_PLAN_NUMBERS:
            frame[column] = pd.to_numeric(frame[column], errors="coerce").astype("float64")
    frame.attrs.update({k: v for k, v in plan.items() if k != "candidates"})
    return frame


def radii_frame(result: Mapping[str, Any]) -> pd.DataFrame:
    """A result's figures at each radius the run tallied (its ``radii``: a job given ``"radii":
    [R′, …]``) in long format: one row per radius and strategy, the radii ascending (the run's own
    R last), the strategies in the server's order.

    Columns: ``merge_radius`` (R′) and ``own`` (whether it is the run's own R); ``strategy`` and
    ``recommended`` (whether the noise table at R′ recommends this row); ``luminance`` (L̂ at R′),
    ``rms_percent`` (RMS% of one iteration at R′ and the run's N_F, N_B) and ``bias_percent``
    (100·(E[C] at R′ − L)/L, against the R → 0 reference: the error no number of iterations
    removes), each with its ``_stderr``; ``bias_source`` (``quadrature`` or ``monte_carlo``),
    ``respects_fixed``; ``merges_plane1``, ``merges_plane2``, ``merges_plane3`` (the radius's merge
    events per iteration at planes 1, 2 and 3, the same on each of its rows). Missing figures are
    ``NaN``. Empty (with these columns) for a run without ``radii``. ``frame.attrs["radii"]`` keeps
    each radius's members but its rows.
    """
    radii = list(result.get("radii") or [])
    records = []
    for radius in radii:
        merges = list(radius.get("merges_per_iteration") or []) + [None, None, None]
        for row in radius.get("rows") or []:
            record: Dict[str, Any] = {
                "merge_radius": radius.get("merge_radius"),
                "own": radius.get("own"),
                "strategy": row.get("strategy"),
                "recommended": row.get("strategy") == radius.get("recommended"),
            }
            record.update({k: v for k, v in row.items() if k not in record})
            for plane in range(3):
                record[f"merges_plane{plane + 1}"] = merges[plane]
            records.append(record)
    frame = _frame(records, _columns(records, RADII_COLUMNS))
    if records:
        for column in _RADII_NUMBERS:
            frame[column] = pd.to_numeric(frame[column], errors="coerce").astype("float64")
    frame.attrs["radii"] = [{k: v for k, v in radius.items() if k != "rows"} for radius in radii]
    return frame
