"""The client against a real optimis server (see conftest.py), plus its retries against a stub."""

from __future__ import annotations

import contextlib
import http.server
import json
import math
import socket
import threading
import time
import uuid
from typing import Any, Callable, Dict, Iterator, List, Tuple, Type

import requests

import numpy as np
import pandas as pd
import pytest
import urllib3

from optimis_client import (
    ApiError,
    Client,
    JobFailed,
    OptimisError,
    RequestTimeout,
    ResponseTooLarge,
    ServerUnreachable,
    UnexpectedRedirect,
    WaitTimeout,
    WeightFunction,
    effective_weights_frame,
    model_path,
    noise_table_frame,
)

# A brute-force job that takes well under a second.
FAST: Dict[str, Any] = {
    "engine": "brute",
    "light_paths": 20000,
    "camera_paths": 200,
    "merge_radius": 0.02,
    "iterations": 30,
    "seed": 1,
}
# The paper's configuration (its Table 1 applies) at 2,000 iterations: about a second.
PAPER: Dict[str, Any] = {"preset": "paper-table1", "iterations": 2000, "seed": 1}
# A brute-force job at the paper's N_F that runs for minutes: something to cancel.
LONG: Dict[str, Any] = {"engine": "brute", "iterations": 100000, "seed": 9}


def missing(value: Any) -> bool:
    """None, NaN or pandas' NA: what a JSON null becomes in a DataFrame."""
    if value is None or value is pd.NA:
        return True
    return isinstance(value, float) and math.isnan(value)


def same(frame_value: Any, json_value: Any) -> bool:
    """A DataFrame cell holds the JSON value: equal, or both missing."""
    if json_value is None:
        return missing(frame_value)
    if isinstance(json_value, list):
        return list(frame_value) == json_value
    return bool(frame_value == json_value)


@pytest.fixture(scope="module")
def done(server: Any) -> Iterator[Dict[str, Dict[str, Any]]]:
    """Jobs several tests read, each run once: the fast one, the paper's (seeds 1 and 2)."""
    with Client(server.url, token=server.token) as c:
        submitted = {
            "fast": c.submit(FAST),
            "paper": c.submit(PAPER),
            "paper2": c.submit({**PAPER, "seed": 2}),
        }
        yield {name: c.wait(job["id"], timeout=120) for name, job in submitted.items()}


def test_submit_and_wait(client: Client) -> None:
    """A submitted job is queued with its name, labels and notes; wait() follows it to success."""
    job = client.submit(FAST, name="fast", labels={"suite": "python-client"}, notes="a quick one")
    assert job["state"] in ("queued", "running", "succeeded")
    assert job["spec"]["name"] == "fast" and job["spec"]["labels"] == {"suite": "python-client"}
    seen: List[Dict[str, Any]] = []
    final = client.wait(job["id"], timeout=120, progress=seen.append)
    assert final["id"] == job["id"] and final["state"] == "succeeded"
    assert final["progress"]["iterations_done"] == FAST["iterations"]
    assert seen and seen[-1]["state"] == "succeeded"
    assert client.job(job["id"])["state"] == "succeeded"


def test_idempotent_submission(client: Client) -> None:
    """The same Idempotency-Key and document return the original job."""
    key = f"python-client-{uuid.uuid4()}"
    first = client.submit({**FAST, "seed": 11}, idempotency_key=key)
    again = client.submit({**FAST, "seed": 11}, idempotency_key=key)
    assert again["id"] == first["id"]
    client.wait(first["id"], timeout=120)


def test_noise_table_matches_result(client: Client, done: Dict[str, Dict[str, Any]]) -> None:
    """The DataFrame is the result's noise table row for row, every field's value equal."""
    for name in ("fast", "paper"):
        job_id = done[name]["id"]
        result = client.result(job_id)
        table = client.noise_table(job_id)
        rows = result["noise_table"]
        assert len(table) == len(rows)
        assert list(table["strategy"]) == [row["strategy"] for row in rows]
        for (_, frame_row), row in zip(table.iterrows(), rows):
            for key, value in row.items():
                where = f"job {job_id} {row['strategy']}.{key}"
                assert same(frame_row[key], value), f"{where}: {frame_row[key]!r} != {value!r}"
        # The same document converted without the server gives the same table.
        pd.testing.assert_frame_equal(noise_table_frame(result), table)


def test_paper_figures_beside_paper_preset(client: Client, done: Dict[str, Dict[str, Any]]) -> None:
    """The paper's Table 1 is beside the paper's configuration, and only there."""
    table = client.noise_table(done["paper"]["id"]).set_index("strategy")
    assert table.loc["switch", "paper_luminance"] == pytest.approx(26.352e-5, rel=1e-12)
    assert table.loc["switch", "paper_rms_percent"] == pytest.approx(61.0)
    assert table.loc["switch", "paper_case"] == 4
    published = {"plane1": 1, "plane2": 2, "plane3": 3, "switch": 4, "optimal": 5}
    assert {s: int(c) for s, c in table["paper_case"].dropna().items()} == published
    assert table.drop(index=list(published))["paper_luminance"].isna().all()
    # The fast job's configuration is not the paper's: no published figures.
    fast = client.noise_table(done["fast"]["id"])
    assert fast[["paper_luminance", "paper_rms_percent", "paper_case"]].isna().all().all()


def test_weights_history_and_lambda(client: Client, done: Dict[str, Dict[str, Any]]) -> None:
    """weights(lam=0) flattens the in-sample table's cells; history is one row per checkpoint and strategy."""
    job_id = done["paper"]["id"]
    cells = client.result(job_id, lam=0)["weights"]
    weights = client.weights(job_id, lam=0)
    assert cells and len(weights) == len(cells)
    for column in ("r2_lo", "r2_hi", "r3_lo", "r3_hi", "phi_lo_rad", "phi_hi_rad", "w0", "w1", "w2",
                   "w0_stderr", "w1_stderr", "w2_stderr", "samples", "status"):
        assert column in weights.columns
    for (_, row), cell in zip(weights.iterrows(), cells):
        assert same(row["r3_lo"], cell["r3"][0]) and same(row["r3_hi"], cell["r3"][1])
        assert same(row["w1"], cell["w1"]) and same(row["w1_stderr"], cell["w1_stderr"])
        assert row["status"] == cell["status"] and row["samples"] == cell["samples"]

    history = client.history(job_id)
    # docs/csv.md's history columns, as the server's CSV has them.
    assert list(history.columns[:5]) == ["iterations", "strategy", "luminance", "luminance_stderr", "rms_percent"]
    last = history[history["iterations"] == history["iterations"].max()].iloc[0]
    expected = abs(last["luminance"]) * last["rms_percent"] / 100 / math.sqrt(last["iterations"])
    assert same(last["luminance_stderr"], expected)
    assert history["iterations"].max() == PAPER["iterations"]
    strategies = {row["strategy"] for row in client.result(job_id)["noise_table"]}
    assert set(history["strategy"]) <= strategies and "switch" in set(history["strategy"])


def sums_to_one(f: WeightFunction, x2: np.ndarray, x3: np.ndarray) -> np.ndarray:
    """The weights (w0, w1, w2) of `f` on the model scene's join paths (x2, x3), checked to sum to 1."""
    w = f.weights(**model_path(f, x2, x3).inputs())
    assert w.shape == (len(x2), 3)
    np.testing.assert_allclose(w.sum(axis=-1), 1.0, rtol=0, atol=1e-12 * (1 + f.beta_sum))
    return w


def test_weights_artifact(client: Client, done: Dict[str, Dict[str, Any]]) -> None:
    """The artifact is the recommended row's weight function, and the numpy evaluator reads it."""
    job_id = done["paper"]["id"]
    result = client.result(job_id)
    recommended = result["recommended"]["strategy"]
    artifact = client.weights_artifact(job_id)
    assert artifact["format"] == "optimis-weights" and artifact["version"] == 1
    assert artifact["strategy"] == recommended and artifact["recommended"] is True
    assert artifact["provenance"]["job_id"] == job_id
    assert artifact["provenance"]["iterations"] == PAPER["iterations"]
    assert artifact["provenance"]["fingerprint"] == result["fingerprint"]
    assert artifact["scene"]["merge_radius"] == 0.003 and artifact["scene"]["camera_paths"] == 100
    # A per-path recommendation has no table (the result's weights are empty too), a fitted one has.
    assert (artifact["kind"] == "heuristic") == (not result["weights"])
    if artifact["kind"] == "heuristic":
        assert artifact["cells"] is None and artifact["table"] == []
        assert [h["name"] for h in artifact["heuristics"]] == [recommended]
    # Evaluated on a few join paths: the weights sum to 1, and keep the paper's fixed w0 = 0.
    f = client.weight_function(job_id)
    assert f.strategy == recommended and f.kind == artifact["kind"]
    row = next(r for r in result["noise_table"] if r["strategy"] == recommended)
    assert row["respects_fixed"]
    x2 = np.array([[0.1, 0.0], [0.3, -0.2], [-0.05, 0.4], [1.2, 0.7]])
    x3 = np.array([[0.01, 0.0], [0.3, 0.05], [-0.6, 1.1], [0.015, -0.01]])
    w = sums_to_one(f, x2, x3)
    assert (w[:, 0] == 0.0).all()

    # Any row by name: a per-path one is a heuristic, the stacked optimum a table and its β.
    balance = client.weights_artifact(job_id, strategy="balance_planes23")
    assert balance["strategy"] == "balance_planes23" and balance["kind"] == "heuristic"
    assert balance["recommended"] is (recommended == "balance_planes23")
    stacked = client.weight_function(job_id, strategy="optimal_stacked")
    assert stacked.strategy == "optimal_stacked" and stacked.kind == "stack"
    assert stacked.cells is not None and stacked.cells.cells == 52 and stacked.heuristics
    assert (sums_to_one(stacked, x2, x3)[:, 0] == 0.0).all()


def test_effective_weights(client: Client, done: Dict[str, Dict[str, Any]]) -> None:
    """One row per (r2, r3) bin; where a bin carries light, w0 + w1 + w2 = 1 with standard errors."""
    job_id = done["paper"]["id"]
    result = client.result(job_id)
    recommended = result["recommended"]["strategy"]
    frame = client.effective_weights(job_id, paths=5000)
    assert frame.attrs["strategy"] == recommended and frame.attrs["paths_per_side"] == 5000
    assert frame.attrs["kind"] in ("table", "heuristic", "stack")
    assert frame.attrs["camera_paths_reaching_plane3"] > 0
    assert frame.attrs["luminance"] == pytest.approx(result["reference_luminance"], rel=0.1)
    cells = done["paper"]["spec"]["cells"]
    assert len(frame) == len(cells["r2_edges"]) * len(cells["r3_edges"])
    columns = ["strategy", "kind", "r2_lo", "r2_hi", "r3_lo", "r3_hi", "paths", "luminance_share"]
    columns += [f"w{m}{s}" for s in ("", "_stderr", "_sampling_stderr", "_fit_stderr") for m in range(3)]
    assert set(columns) <= set(frame.columns)
    assert (frame["strategy"] == recommended).all() and (frame["kind"] == frame.attrs["kind"]).all()
    # The tail bin is open on both axes.
    assert math.isnan(frame["r2_hi"].iloc[-1]) and math.isnan(frame["r3_hi"].iloc[-1])
    lit = frame[frame["w1"].notna()]
    assert len(lit) > 10 and (lit["paths"] > 0).all()
    np.testing.assert_allclose(lit["w0"] + lit["w1"] + lit["w2"], 1.0, rtol=0, atol=1e-9)
    assert (lit["w0"] == 0.0).all()  # the paper's fixed weight, kept by the recommendation
    for m in range(3):
        assert (lit[f"w{m}_stderr"] >= 0).all() and (lit[f"w{m}_sampling_stderr"] >= 0).all()
    assert (lit["w1_stderr"] > 0).any()
    assert frame["luminance_share"].sum() == pytest.approx(1.0, abs=1e-9)
    # No light, no weights.
    assert (frame.loc[frame["w1"].isna(), "luminance_share"] == 0).all()
    if frame.attrs["kind"] == "heuristic":
        assert frame[["w0_fit_stderr", "w1_fit_stderr", "w2_fit_stderr"]].isna().all().all()
    # The same document converted without the client's call gives the same frame.
    raw = client.request("GET", f"/v1/jobs/{job_id}/effective", params={"paths": 5000}).json()
    pd.testing.assert_frame_equal(effective_weights_frame(raw), frame)
    first = int(lit.index[0])
    assert raw["bins"][first]["w"] == [frame.loc[first, f"w{m}"] for m in range(3)]
    assert raw["bins"][first]["stderr"] == [frame.loc[first, f"w{m}_stderr"] for m in range(3)]

    # A fitted row has fit errors too; its SE combines sampling and fit.
    stacked = client.effective_weights(job_id, strategy="optimal_stacked", paths=2000)
    assert stacked.attrs["strategy"] == "optimal_stacked" and stacked.attrs["kind"] == "stack"
    lit = stacked[stacked["w1"].notna()]
    np.testing.assert_allclose(lit["w0"] + lit["w1"] + lit["w2"], 1.0, rtol=0, atol=1e-9)
    assert lit["w1_fit_stderr"].notna().all() and (lit["w1_fit_stderr"] > 0).any()
    combined = np.hypot(lit["w1_sampling_stderr"], lit["w1_fit_stderr"])
    np.testing.assert_allclose(lit["w1_stderr"], combined, rtol=1e-9, atol=1e-15)


def test_weights_arguments_are_checked(
    client: Client, done: Dict[str, Dict[str, Any]], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A bad `paths` or `strategy` raises ValueError before sending; the server's 422 names the field."""
    job_id = done["paper"]["id"]
    sent: List[Any] = []
    with monkeypatch.context() as patch:
        patch.setattr(client, "request", lambda *args, **kwargs: sent.append(args))
        for paths in (999, 1_000_001, 0, -5000, 2000.0, "5000", True):
            with pytest.raises(ValueError, match="paths"):
                client.effective_weights(job_id, paths=paths)  # type: ignore[arg-type]
        for strategy in ("Optimal", "", "a" * 65, "optimal stacked", "optimal_stacked\n", 3):
            with pytest.raises(ValueError, match="strategy"):
                client.effective_weights(job_id, strategy=strategy)  # type: ignore[arg-type]
            with pytest.raises(ValueError, match="strategy"):
                client.weights_artifact(job_id, strategy=strategy)  # type: ignore[arg-type]
    assert sent == []
    # The bounds are inclusive.
    assert client.effective_weights(job_id, paths=1000).attrs["paths_per_side"] == 1000
    # The server's own checks surface as ApiError 422 naming the field.
    with pytest.raises(ApiError) as caught:
        client.request("GET", f"/v1/jobs/{job_id}/effective", params={"paths": 10})
    assert caught.value.status == 422 and caught.value.field == "paths"
    for call in (client.effective_weights, client.weights_artifact):
        with pytest.raises(ApiError) as caught:
            call(job_id, strategy="no_such_row")
        assert caught.value.status == 422 and caught.value.field == "strategy"
    with pytest.raises(ApiError) as caught:
        client.weights_artifact(10**9)
    assert caught.value.status == 404


def test_labels_filter(client: Client) -> None:
    """jobs(label="k=v") lists the jobs with that label, and only them."""
    tag = uuid.uuid4().hex[:12]
    a = client.submit({**FAST, "seed": 21}, labels={"suite": f"a-{tag}"})
    b = client.submit({**FAST, "seed": 22}, labels={"suite": f"b-{tag}", "other": "x"})
    for job in (a, b):
        client.wait(job["id"], timeout=120)
    assert [j["id"] for j in client.jobs(label=f"suite=a-{tag}")] == [a["id"]]
    assert [j["id"] for j in client.jobs(label=("suite", f"b-{tag}"), state="succeeded")] == [b["id"]]
    assert client.jobs(label=f"suite=c-{tag}") == []


def test_jobs_follows_pages(client: Client, done: Dict[str, Dict[str, Any]]) -> None:
    """jobs() follows next_cursor across pages up to its limit, newest first."""
    everything = client.jobs(limit=None)
    assert len(everything) >= 3
    client.page_size = 2
    paged = client.jobs(limit=len(everything))
    assert [j["id"] for j in paged] == [j["id"] for j in everything]
    assert [j["id"] for j in client.jobs(limit=3)] == [j["id"] for j in everything[:3]]
    ids = [j["id"] for j in everything]
    assert ids == sorted(ids, reverse=True)


def test_compare(client: Client, done: Dict[str, Dict[str, Any]]) -> None:
    """compare() is long: one row per strategy and run, with every ratio and its standard error."""
    ids = [done["paper"]["id"], done["paper2"]["id"]]
    frame = client.compare(ids)
    strategies = [row["strategy"] for row in client.result(ids[0])["noise_table"]]
    assert len(frame) == 2 * len(set(frame["strategy"]))
    assert set(frame["strategy"]) <= set(strategies) and "switch" in set(frame["strategy"])
    for column in ("luminance", "luminance_stderr", "rms_percent", "rms_percent_stderr", "luminance_ratio",
                   "luminance_ratio_stderr", "luminance_difference", "luminance_difference_stderr", "z",
                   "rms_ratio", "rms_ratio_stderr"):
        assert column in frame.columns
    assert list(frame["job_id"].unique()) == ids
    assert list(frame["run"].unique()) == [f"job {i}" for i in ids]
    switch = frame[frame["strategy"] == "switch"].set_index("run_index")
    assert switch.loc[0, ["luminance_ratio", "rms_ratio"]].isna().all()
    for column in ("luminance_ratio", "luminance_ratio_stderr", "rms_ratio", "rms_ratio_stderr"):
        value = switch.loc[1, column]
        assert math.isfinite(value) and value > 0, column
    assert frame.attrs["notes"] and len(frame.attrs["runs"]) == 2


def test_sweep(client: Client) -> None:
    """A two-point sweep runs both points; its table has every row of the server's."""
    sweep = client.sweep({
        "base": {**FAST, "labels": {"suite": "sweep"}},
        "axes": [{"field": "merge_radius", "values": [0.01, 0.02]}],
        "mode": "grid",
    }, name="R", labels={"owner": "ana"}, notes="two radii")
    assert len(sweep["points"]) == 2
    seen: List[Dict[str, Any]] = []
    final = client.wait_sweep(sweep["id"], timeout=120, progress=seen.append)
    assert final["state"] == "succeeded" and seen[-1]["state"] == "succeeded"
    table = client.sweep_table(sweep["id"])
    rows = client.request("GET", f"/v1/sweeps/{sweep['id']}/table").json()["rows"]
    assert len(table) == len(rows) > 0
    assert list(table.columns[:2]) == ["point", "merge_radius"]
    assert sorted(set(table["merge_radius"])) == [0.01, 0.02]
    assert [(r["point"], r["strategy"]) for r in rows] == list(zip(table["point"], table["strategy"]))
    assert all(same(v, r["rms_percent"]) for v, r in zip(table["rms_percent"], rows))
    runs = client.jobs(sweep=sweep["id"])
    assert len(runs) == 2
    # name=, labels= and notes= reach every run, as submit's reach a job.
    assert sorted(r["spec"]["name"] for r in runs) == ["R: merge_radius=0.01", "R: merge_radius=0.02"]
    assert all(r["spec"]["labels"] == {"suite": "sweep", "owner": "ana"} for r in runs)
    assert all(r["spec"]["notes"] == "two radii" for r in runs)


def test_predict_and_budget(client: Client) -> None:
    """A job with noise components predicts another budget and plans the fastest one."""
    job = client.submit({"preset": "paper-table1", "light_paths": 1000000, "iterations": 2000,
                         "noise_components": True, "seed": 3})
    client.wait(job["id"], timeout=120)
    prediction = client.predict(job["id"], light_paths=2000000, camera_paths=100)
    assert prediction["job_id"] == job["id"]
    assert prediction["budget"] == {"light_paths": 2000000, "camera_paths": 100}
    assert any(row["strategy"] == "switch" and row["rms_percent"] for row in prediction["noise_table"])
    plan = client.budget(job["id"], target_rms=1, light_cost=2e-8, camera_cost=1e-7, iteration_cost=0.001)
    assert plan["job_id"] == job["id"] and plan["partial"] is False
    assert plan["costs"]["source"] == "given"
    # No costs: the reference's, as `optimis budget` and the dashboard take them.
    reference = client.budget(job["id"], target_rms=1)
    assert reference["costs"] == {"light_path": 7.3e-9, "camera_path": 4.1e-6, "iteration": 1.9e-4,
                                  "merge": 8e-8, "pixels": 1e6, "source": "reference"}
    # Without target_rmse there is no error plan.
    assert "error_plan" not in reference or reference["error_plan"] is None
    # A job without noise components cannot predict: 409.
    plain = client.submit({**FAST, "seed": 31})
    client.wait(plain["id"], timeout=120)
    with pytest.raises(ApiError) as caught:
        client.predict(plain["id"], light_paths=20000, camera_paths=200)
    assert caught.value.status == 409


def test_moments_study_merge_extend(client: Client) -> None:
    """Moments of two seeds make a study; one merges into a third job; a job extends."""
    jobs = [client.submit({**FAST, "seed": seed}) for seed in (41, 42, 43)]
    for job in jobs:
        client.wait(job["id"], timeout=120)
    documents = [client.moments(job["id"]) for job in jobs[:2]]
    assert documents[0]["kind"] == "optimis-moments"
    study = client.study(documents)
    assert study["state"] == "succeeded" and study["progress"]["iterations_done"] == 2 * FAST["iterations"]
    merged = client.merge(jobs[2]["id"], documents[0])
    assert merged["iterations"] == 2 * FAST["iterations"]
    with pytest.raises(ApiError) as caught:
        client.merge(jobs[2]["id"], documents[0])  # those iterations are counted already
    assert caught.value.status == 409
    extended = client.extend(jobs[1]["id"], 10)
    assert extended["progress"]["iterations_total"] == FAST["iterations"] + 10
    assert client.wait(jobs[1]["id"], timeout=120)["progress"]["iterations_done"] == FAST["iterations"] + 10
    with pytest.raises(ValueError):
        client.extend(jobs[1]["id"])


def test_references(client: Client) -> None:
    """The published tables include the paper's Table 1 with its switch row."""
    tables = {t["id"]: t for t in client.references()}
    rows = {r["strategy"]: r for r in tables["ershov2020-table1"]["rows"]}
    assert rows["switch"]["luminance"] == pytest.approx(26.352e-5)


def test_invalid_job_names_field(client: Client) -> None:
    """A 422 is an ApiError carrying the problem: status, title, detail and the field."""
    with pytest.raises(ApiError) as caught:
        client.submit({"preset": "paper-table1", "merge_radius": -1})
    err = caught.value
    assert isinstance(err, OptimisError)
    assert err.status == 422 and err.field == "merge_radius"
    assert err.title == "Unprocessable Entity"
    assert "merge_radius" in err.detail and err.detail in str(err)
    assert "(422)" in str(err) and "[field: merge_radius]" in str(err)


def test_not_found(client: Client) -> None:
    """An unknown job is a 404 ApiError."""
    with pytest.raises(ApiError) as caught:
        client.job(987654321)
    assert caught.value.status == 404 and caught.value.field is None


def test_cancelled_job_fails_wait(client: Client) -> None:
    """wait() times out on a running job, then raises JobFailed once it is cancelled; it can be deleted."""
    job = client.submit(LONG)
    # Until it runs (a guard against a hang, not a measure of speed).
    give_up = time.monotonic() + 120
    while client.job(job["id"])["state"] == "queued":
        if time.monotonic() > give_up:
            pytest.fail(f"job {job['id']} was still queued after 120 s")
        time.sleep(0.05)
    try:
        with pytest.raises(TimeoutError) as timed_out:
            client.wait(job["id"], timeout=0.5)
        assert isinstance(timed_out.value, WaitTimeout) and timed_out.value.state == "running"
    finally:
        client.cancel(job["id"])
    with pytest.raises(JobFailed) as caught:
        client.wait(job["id"], timeout=120)
    assert caught.value.state == "cancelled" and caught.value.job["id"] == job["id"]
    assert f"job {job['id']} cancelled" in str(caught.value)
    with pytest.raises(ApiError) as conflict:
        client.cancel(job["id"])
    assert conflict.value.status == 409
    client.delete(job["id"])
    with pytest.raises(ApiError) as gone:
        client.job(job["id"])
    assert gone.value.status == 404


def test_server_unreachable() -> None:
    """Nothing listening: ServerUnreachable names the URL and says how to start a server."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))  # bound, never listening: connections are refused
        url = f"http://127.0.0.1:{sock.getsockname()[1]}"
        with pytest.raises(ServerUnreachable) as caught:
            Client(url, token="", timeout=5).jobs()
    message = str(caught.value)
    assert url in message and "is the server running?" in message and "optimis serve" in message
    assert isinstance(caught.value, OptimisError) and isinstance(caught.value, ConnectionError)


def test_missing_token(server: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the token the server answers 401, an ApiError."""
    monkeypatch.delenv("OPTIMIS_TOKEN", raising=False)
    for client in (Client(server.url), Client(server.url, token="")):
        with pytest.raises(ApiError) as caught:
            client.jobs()
        assert caught.value.status == 401 and "(401)" in str(caught.value)
    monkeypatch.setenv("OPTIMIS_TOKEN", server.token)
    assert isinstance(Client(server.url).jobs(limit=1), list)


class _Busy(http.server.BaseHTTPRequestHandler):
    """A stub that answers 429 (Retry-After: 0) `busy` times, then 200."""

    busy = 2
    calls = 0

    def do_GET(self) -> None:  # noqa: N802 (the handler's API)
        type(self).calls += 1
        if type(self).calls <= type(self).busy:
            body = json.dumps({"type": "urn:problem-type:optimis:too-many-requests", "title": "Too Many Requests",
                               "status": 429, "detail": "the queue is full"}).encode()
            self.send_response(429)
            self.send_header("Retry-After", "0")
            self.send_header("Content-Type", "application/problem+json")
        else:
            body = json.dumps({"references": []}).encode()
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args: Any) -> None:
        """Quiet."""


@pytest.mark.parametrize("busy, retries, succeeds", [(2, 5, True), (3, 2, False)])
def test_retries_429(busy: int, retries: int, succeeds: bool) -> None:
    """429 with Retry-After is retried, at most max_retries times (a loopback stub, not the server)."""
    handler = type("Handler", (_Busy,), {"busy": busy, "calls": 0})
    stub = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=stub.serve_forever, daemon=True)
    thread.start()
    try:
        client = Client(f"http://127.0.0.1:{stub.server_address[1]}", token="", max_retries=retries)
        if succeeds:
            assert client.references() == []
            assert handler.calls == busy + 1
        else:
            with pytest.raises(ApiError) as caught:
                client.references()
            assert caught.value.status == 429 and caught.value.detail == "the queue is full"
            assert handler.calls == retries + 1
    finally:
        stub.shutdown()
        stub.server_close()


# -- transport bounds, against loopback stand-ins -----------------------------------------------

MIB = 1024 * 1024


@contextlib.contextmanager
def stand_in(handler: Type[http.server.BaseHTTPRequestHandler]) -> Iterator[str]:
    """A stand-in HTTP server on an ephemeral loopback port answering with `handler`; yields its URL."""
    stub = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=stub.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{stub.server_address[1]}"
    finally:
        stub.shutdown()
        stub.server_close()


class _Quiet(http.server.BaseHTTPRequestHandler):
    """A handler that logs nothing."""

    def log_message(self, *args: Any) -> None:
        """Quiet."""


class _Trickle(_Quiet):
    """Answers a GET one byte every half second — in its headers, or in a body of 1,000 declared
    bytes — and gives up (closing the connection) after 12 s; answers /readyz at once."""

    where = "body"

    def do_GET(self) -> None:  # noqa: N802 (the handler's API)
        if self.path == "/readyz":
            self.send_response(200)
            self.send_header("Content-Length", "0")
            self.end_headers()
            return
        if self.where == "headers":
            self.wfile.write(b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nX-Slow: ")
        else:
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", "1000")
            self.end_headers()
        give_up = time.monotonic() + 12
        try:
            while time.monotonic() < give_up:
                self.wfile.write(b" " if self.where == "body" else b"a")
                time.sleep(0.5)
        except OSError:
            pass  # the client hung up
        self.close_connection = True


@pytest.mark.parametrize("where, own_session", [("body", False), ("headers", False), ("body", True)])
def test_timeout_bounds_the_whole_call(where: str, own_session: bool) -> None:
    """`timeout` bounds a whole call, not each socket read: a stand-in trickling its answer a byte
    every 0.5 s (which no per-read timeout of 1.5 s would ever stop) is given up after 1.5 s."""
    if own_session and not hasattr(urllib3.HTTPResponse, "shutdown"):
        pytest.skip("urllib3 < 2.3 cannot end a body that ends with the connection's close (see Client)")
    handler = type("Handler", (_Trickle,), {"where": where})
    with stand_in(handler) as url:
        session = requests.Session() if own_session else None
        client = Client(url, token="", timeout=1.5, session=session)
        started = time.monotonic()
        with pytest.raises(RequestTimeout) as caught:
            client.references()
        elapsed = time.monotonic() - started
        assert client.ready()  # the client is still usable
        client.close()
    assert 1.4 <= elapsed < 10, f"the call took {elapsed:.1f} s"
    err = caught.value
    assert isinstance(err, TimeoutError) and isinstance(err, ServerUnreachable) and isinstance(err, OptimisError)
    assert err.seconds == 1.5 and err.method == "GET" and err.request_url == url + "/v1/references"
    assert "1.5 s" in str(err) and url + "/v1/references" in str(err) and "timeout" in str(err)


class _Big(_Quiet):
    """Answers a GET with `{"references": []}` padded with spaces to `size` bytes, in chunks of
    1 MiB: framed by `Content-Length` (declaring `declared` bytes: more than it sends, to stand for
    a huge answer), chunked, or ended by closing the connection. Never more than 16 MiB."""

    framing = "length"
    size = 16 * MIB
    declared = 300 * MIB

    def do_GET(self) -> None:  # noqa: N802 (the handler's API)
        if self.framing == "chunked":
            self.protocol_version = "HTTP/1.1"
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        if self.framing == "length":
            self.send_header("Content-Length", str(self.declared))
        elif self.framing == "chunked":
            self.send_header("Transfer-Encoding", "chunked")
        self.end_headers()
        body = b'{"references": []}'.ljust(self.size)
        try:
            for start in range(0, len(body), MIB):
                chunk = body[start:start + MIB]
                if self.framing == "chunked":
                    chunk = b"%x\r\n%s\r\n" % (len(chunk), chunk)
                self.wfile.write(chunk)
            if self.framing == "chunked":
                self.wfile.write(b"0\r\n\r\n")
        except OSError:
            pass  # the client hung up
        self.close_connection = True


@pytest.mark.parametrize("framing", ["length", "chunked", "close"])
def test_max_response_bytes(framing: str) -> None:
    """An answer larger than max_response_bytes is refused — from its Content-Length before any of
    it is read, else while it streams (chunked, or ended by the connection's close) — naming the
    bound and how to raise it; raised, the same answer is read."""
    handler = type("Handler", (_Big,), {"framing": framing})
    with stand_in(handler) as url:
        client = Client(url, token="", max_response_bytes=MIB)
        assert client.max_response_bytes == MIB
        with pytest.raises(ResponseTooLarge) as caught:
            client.references()
        err = caught.value
        assert isinstance(err, OptimisError)
        assert err.limit == MIB and err.method == "GET" and err.url == url + "/v1/references"
        assert "max_response_bytes" in str(err) and f"{MIB:,}" in str(err)
        if framing == "length":
            assert err.size == 300 * MIB and f"{300 * MIB:,}" in str(err)
        else:
            assert err.size is None
        if framing != "length":  # (that one declares more than it sends)
            client.max_response_bytes = 16 * MIB
            assert client.references() == []
        client.close()


class _Recorder(_Quiet):
    """Records every request it gets (method, path, Authorization) and answers 200 with JSON."""

    seen: List[Tuple[str, str, Any]] = []

    def _answer(self) -> None:
        type(self).seen.append((self.command, self.path, self.headers.get("Authorization")))
        self.rfile.read(int(self.headers.get("Content-Length") or 0))
        body = json.dumps({"id": 1, "state": "queued", "references": []}).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    do_GET = do_POST = do_DELETE = _answer  # noqa: N815 (the handler's API)


class _Redirect(_Quiet):
    """Answers every request with `status` and `Location: target` + the request's path."""

    status = 307
    target = ""

    def _answer(self) -> None:
        self.rfile.read(int(self.headers.get("Content-Length") or 0))
        self.send_response(self.status)
        self.send_header("Location", self.target + self.path)
        self.send_header("Content-Length", "0")
        self.end_headers()

    do_GET = do_POST = do_DELETE = _answer  # noqa: N815 (the handler's API)


CALLS: Dict[str, Tuple[str, Callable[[Client], Any]]] = {
    "POST": ("/v1/jobs", lambda client: client.submit(FAST)),
    "GET": ("/v1/jobs/1", lambda client: client.job(1)),
    "DELETE": ("/v1/jobs/1", lambda client: client.delete(1)),
}


@pytest.mark.parametrize(
    "method, status",
    [("POST", 307), ("POST", 308), ("POST", 303), ("POST", 302), ("GET", 301), ("GET", 302), ("DELETE", 307)],
)
def test_redirect_not_followed(method: str, status: int) -> None:
    """A redirect is never followed: the request (and its token) is not re-sent to the Location —
    a second stand-in there receives nothing — and the error names the status and the Location."""
    seen: List[Tuple[str, str, Any]] = []
    with stand_in(type("Recorder", (_Recorder,), {"seen": seen})) as elsewhere:
        redirect = type("Redirect", (_Redirect,), {"status": status, "target": elsewhere})
        with stand_in(redirect) as url:
            path, call = CALLS[method]
            with Client(url, token="secret-token") as client:
                with pytest.raises(UnexpectedRedirect) as caught:
                    call(client)
    assert seen == []
    err = caught.value
    assert isinstance(err, OptimisError)
    assert err.status == status and err.location == elsewhere + path
    assert err.method == method and err.url == url + path
    assert str(status) in str(err) and elsewhere + path in str(err)
    assert "secret-token" not in str(err)


class _HugeRedirect(_Quiet):
    """Answers 302 with a Location and a body declared 300 MiB long, of which it sends nothing."""

    def do_GET(self) -> None:  # noqa: N802 (the handler's API)
        self.send_response(302)
        self.send_header("Location", "http://127.0.0.1:9/elsewhere")
        self.send_header("Content-Length", str(300 * MIB))
        self.end_headers()
        time.sleep(5)
        self.close_connection = True


def test_redirect_body_not_read() -> None:
    """A redirect is refused as its headers arrive, its body unread (requests reads a redirect's
    whole body even when told not to follow it): no wait for the 300 MiB it announces."""
    with stand_in(_HugeRedirect) as url:
        client = Client(url, token="", timeout=3)
        started = time.monotonic()
        with pytest.raises(UnexpectedRedirect) as caught:
            client.references()
        elapsed = time.monotonic() - started
        client.close()
    assert elapsed < 2, f"the call took {elapsed:.1f} s"
    assert caught.value.status == 302 and caught.value.location == "http://127.0.0.1:9/elsewhere"
