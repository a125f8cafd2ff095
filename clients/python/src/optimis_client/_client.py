"""The HTTP client of an optimis server (``optimis serve``)."""

from __future__ import annotations

import email.utils
import math
import numbers
import os
import re
import time
from datetime import datetime, timezone
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Type, Union
from urllib.parse import urljoin

import pandas as pd
import requests

from ._errors import (
    ApiError,
    JobFailed,
    OptimisError,
    RequestTimeout,
    ResponseTooLarge,
    ServerUnreachable,
    SweepFailed,
    UnexpectedRedirect,
    WaitTimeout,
)
from ._frames import (
    _columns,
    _frame,
    compare_frame,
    history_frame,
    noise_table_frame,
    radii_frame,
    sweep_table_frame,
    weights_frame,
)
from ._transport import Deadline, WatchedAdapter
from .weights import WeightFunction

#: A JSON object as the server sends it.
Json = Dict[str, Any]

#: Where ``optimis serve`` listens by default.
DEFAULT_URL = "http://127.0.0.1:8080"

#: States after which a job (or a sweep) no longer changes.
FINAL_STATES = ("succeeded", "failed", "cancelled")

#: The longest long-poll the server grants one request (``?wait=``, seconds).
MAX_WAIT_SECONDS = 60

#: Seconds one long-poll of :meth:`Client.wait` lasts by default.
DEFAULT_POLL_SECONDS = 30

#: The largest answer a client reads by default (``max_response_bytes``): 64 MiB, twice the largest
#: moments document a server accepts by default (``--document-limit``, 32 MiB).
DEFAULT_MAX_RESPONSE_BYTES = 64 * 1024 * 1024

# Merges and studies may pull documents from peers and merge megabytes: the server gives a study
# 180 s by default (--study-deadline).
_DOCUMENT_TIMEOUT = 200.0

# Bytes of an answer read at a time.
_CHUNK_BYTES = 64 * 1024

# Seconds for a computation the server runs on its heavy pool: a refit of a row at its λ for an
# artifact, the paths of effective weights (as long as a budget gets).
_COMPUTE_TIMEOUT = 120.0

#: What the server accepts as a noise-table row's name in a query (``?strategy=``).
STRATEGY_PATTERN = re.compile(r"[a-z0-9_]{1,64}")

#: The paths per side :meth:`Client.effective_weights` may ask for (the server's bounds; its
#: default is 50,000).
EFFECTIVE_PATHS_RANGE = (1000, 1_000_000)

#: The columns of :func:`effective_weights_frame`, in order (any further member of a bin follows
#: them): those of the server's effective-weights CSV (docs/csv.md) but ``table``,
#: ``paths_per_side`` and ``note``.
EFFECTIVE_COLUMNS = (
    "strategy",
    "kind",
    "r2_lo",
    "r2_hi",
    "r3_lo",
    "r3_hi",
    "paths",
    "luminance_share",
    "w0",
    "w0_stderr",
    "w1",
    "w1_stderr",
    "w2",
    "w2_stderr",
    "w0_sampling_stderr",
    "w1_sampling_stderr",
    "w2_sampling_stderr",
    "w0_fit_stderr",
    "w1_fit_stderr",
    "w2_fit_stderr",
)

# A bin's members holding (technique 0, 1, 2) triples, and the suffix of their columns.
_EFFECTIVE_TRIPLES = (
    ("w", ""),
    ("stderr", "_stderr"),
    ("sampling_stderr", "_sampling_stderr"),
    ("fit_stderr", "_fit_stderr"),
)

# A bin's members that become the columns above.
_EFFECTIVE_MEMBERS = ("r2", "r3", "paths", "luminance_share") + tuple(member for member, _ in _EFFECTIVE_TRIPLES)


def _normalise_url(base_url: str) -> str:
    """`base_url` without a trailing slash, ``http://`` added when it names no scheme."""
    url = base_url.strip().rstrip("/")
    if not url:
        raise ValueError("base_url is empty")
    if "://" not in url:
        url = "http://" + url
    return url


def _reason(err: requests.RequestException) -> str:
    """A short account of a transport failure (requests' own messages run to several lines)."""
    text = str(err)
    for needle, reason in (
        ("Connection refused", "connection refused"),
        ("Connection reset", "connection reset"),
        ("Name or service not known", "unknown host name"),
        ("nodename nor servname", "unknown host name"),
        ("RemoteDisconnected", "the server closed the connection without answering"),
        ("No route to host", "no route to host"),
        ("Network is unreachable", "network unreachable"),
    ):
        if needle in text:
            return reason
    return text.splitlines()[0][:300] if text else type(err).__name__


def _retry_after(header: Optional[str], attempt: int) -> float:
    """Seconds to wait before retrying: the ``Retry-After`` header (seconds or an HTTP date), or
    an exponential back-off from half a second when there is none."""
    if header:
        try:
            return max(0.0, float(header))
        except ValueError:
            pass
        try:
            when = email.utils.parsedate_to_datetime(header)
        except (TypeError, ValueError):
            when = None
        if when is not None:
            if when.tzinfo is None:
                when = when.replace(tzinfo=timezone.utc)
            return max(0.0, (when - datetime.now(timezone.utc)).total_seconds())
    return min(0.5 * 2.0**attempt, 8.0)


def _api_error(method: str, url: str, response: requests.Response) -> ApiError:
    """The :class:`ApiError` of a 4xx/5xx answer: its problem document, or whatever the body is."""
    try:
        problem = response.json()
    except ValueError:
        problem = None
    status = response.status_code
    if isinstance(problem, dict) and "detail" in problem:
        return ApiError(
            int(problem.get("status") or status),
            str(problem.get("title") or response.reason or "Error"),
            str(problem["detail"]),
            problem.get("field"),
            type=problem.get("type"),
            method=method,
            url=url,
            problem=problem,
        )
    body = " ".join(response.text.split())[:200]
    detail = f"{method} {url}: HTTP {status}" + (f" {body}" if body else "")
    return ApiError(status, response.reason or "Error", detail, None, method=method, url=url)


def _source(source: Union[str, Mapping[str, Any]]) -> Json:
    """A merge source: a moments document as is, or a URL as ``{"from": URL}``."""
    if isinstance(source, str):
        return {"from": source}
    if isinstance(source, Mapping):
        return dict(source)
    raise TypeError(f"a source is a moments document (a dict) or a job's URL (a str), not {type(source).__name__}")


def _mark(resource: Mapping[str, Any]) -> Tuple[Any, ...]:
    """What a progress callback is told about: the state and the counts of a job or a sweep."""
    progress = resource.get("progress") or {}
    by_state = progress.get("runs_by_state") or {}
    return (
        resource.get("state"),
        progress.get("iterations_done"),
        progress.get("iterations_total"),
        tuple(sorted(by_state.items())),
    )


def _strategy_params(strategy: Optional[str]) -> Json:
    """The query naming a noise-table row (none: the recommended row), checked as the server
    checks it (:class:`ValueError` otherwise, before anything is sent)."""
    if strategy is None:
        return {}
    if not isinstance(strategy, str) or not STRATEGY_PATTERN.fullmatch(strategy):
        raise ValueError(
            f"strategy must be a noise-table row's name (1 to 64 of a-z, 0-9 and _, e.g. 'optimal_stacked'), "
            f"not {strategy!r}"
        )
    return {"strategy": strategy}


def _effective_paths(paths: Any) -> int:
    """`paths` checked against :data:`EFFECTIVE_PATHS_RANGE` (:class:`ValueError` otherwise)."""
    low, high = EFFECTIVE_PATHS_RANGE
    if isinstance(paths, bool) or not isinstance(paths, numbers.Integral) or not low <= paths <= high:
        raise ValueError(f"paths must be an integer from {low} to {high}, not {paths!r}")
    return int(paths)


def effective_weights_frame(effective: Mapping[str, Any]) -> pd.DataFrame:
    """Effective weights (``GET /v1/jobs/{id}/effective``, or the ``effective`` member of a result
    made by ``optimis run --json``/``optimis report --json``) as a DataFrame: one row per (r2, r3)
    bin, in the document's order (r2-major, then r3).

    Columns: ``strategy`` and ``kind`` (``table``, ``heuristic`` or ``stack``) of the weight
    function; the bin's bounds ``r2_lo``, ``r2_hi``, ``r3_lo``, ``r3_hi`` (an open upper bound, the
    tail bin, is ``NaN``); ``paths`` (sampled paths in the bin) and ``luminance_share``; the
    effective weights ``w0``, ``w1``, ``w2`` — the contribution-weighted averages of each
    technique's weight over the bin's paths, summing to 1 — and their standard errors
    ``w0_stderr`` … (sampling and fit combined), ``w0_sampling_stderr`` … and ``w0_fit_stderr`` …
    (the fit's part; ``NaN`` for a per-path heuristic, which fits nothing). The weights and their
    errors are ``NaN`` in a bin where no sampled path carries light. ``frame.attrs`` keeps the
    document's other members: ``strategy``, ``kind``, ``paths_per_side``,
    ``camera_paths_reaching_plane3`` and ``luminance`` (the paths' estimate of L).
    """
    attrs = {k: v for k, v in effective.items() if k != "bins"}
    records = []
    for b in effective.get("bins") or []:
        record: Dict[str, Any] = {"strategy": effective.get("strategy"), "kind": effective.get("kind")}
        for name in ("r2", "r3"):
            bounds = list(b.get(name) or [None, None]) + [None, None]
            record[f"{name}_lo"], record[f"{name}_hi"] = bounds[0], bounds[1]
        record["paths"] = b.get("paths")
        record["luminance_share"] = b.get("luminance_share")
        for member, suffix in _EFFECTIVE_TRIPLES:
            values = list(b.get(member) or [None, None, None]) + [None, None, None]
            for m in range(3):
                record[f"w{m}{suffix}"] = values[m]
        record.update({k: v for k, v in b.items() if k not in _EFFECTIVE_MEMBERS})
        records.append(record)
    frame = _frame(records, _columns(records, EFFECTIVE_COLUMNS))
    if records:
        for column in EFFECTIVE_COLUMNS[2:]:
            if column != "paths":
                frame[column] = pd.to_numeric(frame[column], errors="coerce").astype("float64")
    frame.attrs.update(attrs)
    return frame


class Client:
    """A client of one optimis server.

    ``base_url`` is the server's address (``http://`` is assumed when it names no scheme);
    ``token`` the bearer token the server requires (default: the ``OPTIMIS_TOKEN`` environment
    variable; ``""`` sends none); ``timeout`` the seconds one request may take in all —
    connecting, sending it and reading its whole answer, not each socket read — else
    :class:`RequestTimeout` (a long-poll gets its waiting time on top; a retry is a new request).
    ``max_response_bytes`` bounds the answer read into memory (default 64 MiB; a larger one raises
    :class:`ResponseTooLarge`). Redirects are never followed: a 3xx answer raises
    :class:`UnexpectedRedirect`, and nothing (neither the body nor the token) is sent to its
    ``Location``. Answers 429 and 503 are retried after their ``Retry-After``, at most
    ``max_retries`` times and while ``retry_deadline`` seconds have not passed; any other 4xx/5xx
    raises :class:`ApiError`, and no answer at all :class:`ServerUnreachable`.

    A ``session`` of your own keeps its adapters: reading its answers' bodies is bounded by
    ``timeout`` all the same (with urllib3 2.3 or later; an older one cannot end a body that
    ends with the connection's close, other than between chunks of 64 KiB), but connecting,
    sending and waiting for the headers only by requests' timeouts of each socket operation.

    Usable as a context manager (the connection pool is closed on exit)::

        with Client("http://127.0.0.1:8080") as client:
            job = client.wait(client.submit({"preset": "paper-table1", "iterations": 10000})["id"])
            print(client.noise_table(job["id"]))
    """

    def __init__(
        self,
        base_url: str = DEFAULT_URL,
        token: Optional[str] = None,
        timeout: float = 30.0,
        *,
        max_retries: int = 5,
        retry_deadline: float = 120.0,
        max_response_bytes: int = DEFAULT_MAX_RESPONSE_BYTES,
        session: Optional[requests.Session] = None,
    ) -> None:
        """Connect to the server at `base_url` (nothing is sent until the first call)."""
        self.base_url = _normalise_url(base_url)
        self.timeout = float(timeout)
        self.max_retries = int(max_retries)
        self.retry_deadline = float(retry_deadline)
        #: The largest answer read into memory, in bytes (raise it for larger documents).
        self.max_response_bytes = int(max_response_bytes)
        #: Jobs asked for per page by :meth:`jobs` (the server allows at most 500).
        self.page_size = 500
        if token is None:
            token = os.environ.get("OPTIMIS_TOKEN")
        if session is None:
            session = requests.Session()
            # Connections whose every socket operation the deadline of a request can end.
            session.mount("http://", WatchedAdapter())
            session.mount("https://", WatchedAdapter())
        self._session = session
        self._session.headers["Accept"] = "application/json"
        if token:
            self._session.headers["Authorization"] = f"Bearer {token}"

    def __repr__(self) -> str:
        """``Client('http://…')`` (never the token)."""
        return f"Client({self.base_url!r})"

    def __enter__(self) -> "Client":
        """The client itself."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the connection pool."""
        self.close()

    def close(self) -> None:
        """Close the connection pool (the client opens a new one if used again)."""
        self._session.close()

    # -- transport ------------------------------------------------------------------------------

    def request(
        self,
        method: str,
        path: str,
        *,
        params: Optional[Mapping[str, Any]] = None,
        json: Any = None,
        headers: Optional[Mapping[str, str]] = None,
        timeout: Optional[float] = None,
    ) -> requests.Response:
        """Send one request to `path` (``/v1/…``) and return the answer (any status below 400),
        its body read (``content``, ``text``, ``json()``).

        `timeout` (default: the client's) bounds the whole request: connecting, sending it and
        reading the entire answer, else :class:`RequestTimeout`. An answer larger than
        ``max_response_bytes`` raises :class:`ResponseTooLarge`, a redirect
        :class:`UnexpectedRedirect` (it is not followed). Retries 429 and 503 after their
        ``Retry-After`` (bounded by ``max_retries`` and ``retry_deadline``; each attempt has
        `timeout`); raises :class:`ApiError` for any other 4xx/5xx and :class:`ServerUnreachable`
        when the server does not answer. The routes without a method of their own (``/solve``,
        ``/evaluate``, the named solves, CSV with ``format=csv``) are reachable through this.
        """
        url = self.base_url + path
        seconds = self.timeout if timeout is None else timeout
        started = time.monotonic()
        attempt = 0
        while True:
            with Deadline(seconds) as deadline:
                response = self._open(method, url, deadline, params=params, json=json, headers=dict(headers or {}))
                self._read(method, url, response, deadline)
            if response.status_code in (429, 503) and attempt < self.max_retries:
                pause = _retry_after(response.headers.get("Retry-After"), attempt)
                if time.monotonic() - started + pause <= self.retry_deadline:
                    attempt += 1
                    time.sleep(pause)
                    continue
            if response.status_code >= 400:
                raise _api_error(method, url, response)
            return response

    def _open(self, method: str, url: str, deadline: Deadline, **kwargs: Any) -> requests.Response:
        """Send a request under `deadline`; its answer, once its headers arrived (the body unread).

        A redirect raises :class:`UnexpectedRedirect` as its headers arrive: requests is never let
        follow one, nor read its body (which it does, unbounded, to prepare the next request
        even when it does not follow it).
        """

        def arrived(response: requests.Response, *args: Any, **hook_kwargs: Any) -> None:
            # A WatchedAdapter's socket is watched from the start; another adapter's from here.
            deadline.watch_answer(response.raw)
            if 300 <= response.status_code < 400:
                response.close()
                location = response.headers.get("Location")
                target = urljoin(response.url or url, location) if location else None
                raise UnexpectedRedirect(response.status_code, target, method, url)

        theirs = self._session.hooks.get("response") or []
        hooks = {"response": [arrived, *([theirs] if callable(theirs) else theirs)]}
        # requests' timeouts of each socket operation, within the time left.
        left = max(deadline.remaining(), 0.001)
        try:
            return self._session.request(
                method, url, timeout=(left, left), stream=True, allow_redirects=False, hooks=hooks, **kwargs
            )
        except requests.RequestException as err:
            raise self._failure(method, url, err, deadline) from err

    def _read(self, method: str, url: str, response: requests.Response, deadline: Deadline) -> None:
        """Read the answer's body into `response` before `deadline`, at most ``max_response_bytes``
        of it: a larger ``Content-Length`` is refused before any of it is read, a body without
        one (chunked, or ended by the connection's close) is stopped at the bound."""
        limit = self.max_response_bytes
        try:
            declared = int(response.headers.get("Content-Length") or "-1")
        except ValueError:
            declared = -1  # urllib3 refuses it as it reads
        try:
            if declared > limit:
                raise ResponseTooLarge(limit, declared, method, url)
            chunks: List[bytes] = []
            size = 0
            for chunk in response.iter_content(_CHUNK_BYTES):
                size += len(chunk)
                if size > limit:
                    raise ResponseTooLarge(limit, None, method, url)
                if deadline.expired():
                    raise RequestTimeout(self.base_url, method, url, deadline.seconds)
                chunks.append(chunk)
            # A body ended by the connection's close ends as well when the deadline shuts it down.
            if deadline.passed:
                raise RequestTimeout(self.base_url, method, url, deadline.seconds)
            # requests' own copy of the body, which content, text and json() read.
            response._content = b"".join(chunks)
        except requests.RequestException as err:
            raise self._failure(method, url, err, deadline) from err
        finally:
            # The connection goes back to the pool when the body was read whole, else is closed.
            response.close()

    def _failure(self, method: str, url: str, err: requests.RequestException, deadline: Deadline) -> OptimisError:
        """The error of a request that failed in transport (under `deadline`)."""
        if isinstance(err, requests.Timeout) or deadline.expired():
            return RequestTimeout(self.base_url, method, url, deadline.seconds)
        if isinstance(err, requests.exceptions.SSLError):
            return OptimisError(f"{method} {url}: TLS failed: {err}")
        if isinstance(err, requests.ConnectionError):
            return ServerUnreachable(self.base_url, _reason(err))
        return OptimisError(f"{method} {url}: {err}")

    def _json(self, method: str, path: str, **kwargs: Any) -> Json:
        """The JSON object a request answered with."""
        response = self.request(method, path, **kwargs)
        try:
            document = response.json()
        except ValueError as err:
            raise OptimisError(f"{method} {self.base_url + path}: the answer is not JSON ({err})") from err
        if not isinstance(document, dict):
            raise OptimisError(f"{method} {self.base_url + path}: the answer is not a JSON object")
        return document

    # -- jobs -----------------------------------------------------------------------------------

    def submit(
        self,
        job: Mapping[str, Any],
        *,
        name: Optional[str] = None,
        labels: Optional[Mapping[str, str]] = None,
        notes: Optional[str] = None,
        idempotency_key: Optional[str] = None,
    ) -> Json:
        """Submit a job (``POST /v1/jobs``) and return its resource (``id``, ``state``, ``spec``, …).

        `job` is a job document: a preset and any fields to override, e.g. ``{"preset":
        "paper-table1", "iterations": 10000, "seed": 1}``; ``"radii": [0.005, 0.01]`` (ascending,
        each below ``merge_radius``, at most 6) tallies those smaller merge radii in the same run,
        for :meth:`radii` and the error plan of :meth:`budget`. `name`, `labels` (merged over the
        document's own) and `notes` describe it without changing the computation. With
        `idempotency_key`, a repeated submission of the same document returns the original job.
        Raises :class:`ApiError` (422, ``field`` naming the bad field) for an invalid document.
        """
        document = dict(job)
        if name is not None:
            document["name"] = name
        if labels is not None:
            document["labels"] = {**(document.get("labels") or {}), **dict(labels)}
        if notes is not None:
            document["notes"] = notes
        headers = {"Idempotency-Key": idempotency_key} if idempotency_key is not None else None
        return self._json("POST", "/v1/jobs", json=document, headers=headers)

    def job(self, id: int) -> Json:
        """A job's resource as it is now (``GET /v1/jobs/{id}``): state, spec, progress, error."""
        return self._json("GET", f"/v1/jobs/{int(id)}")

    def jobs(
        self,
        *,
        state: Optional[str] = None,
        label: Union[str, Tuple[str, str], None] = None,
        sweep: Optional[int] = None,
        limit: Optional[int] = 50,
    ) -> List[Json]:
        """Jobs, newest first (``GET /v1/jobs``), following the pages up to `limit` jobs (``None``: all).

        Filters: `state` (``queued``, ``running``, ``succeeded``, ``failed``, ``cancelled``),
        `label` (``"KEY=VALUE"`` or a ``(key, value)`` pair: jobs whose document has that label),
        `sweep` (the runs of that sweep).
        """
        if isinstance(label, tuple):
            label = f"{label[0]}={label[1]}"
        found: List[Json] = []
        cursor: Optional[str] = None
        while limit is None or len(found) < limit:
            size = max(1, min(500, self.page_size))
            params: Dict[str, Any] = {"limit": size if limit is None else min(size, limit - len(found))}
            if state is not None:
                params["state"] = state
            if label is not None:
                params["label"] = label
            if sweep is not None:
                params["sweep"] = int(sweep)
            if cursor is not None:
                params["cursor"] = cursor
            page = self._json("GET", "/v1/jobs", params=params)
            found.extend(page.get("jobs") or [])
            cursor = page.get("next_cursor")
            if not cursor or not page.get("jobs"):
                break
        return found if limit is None else found[:limit]

    def wait(
        self,
        id: int,
        *,
        timeout: Optional[float] = None,
        progress: Optional[Callable[[Json], None]] = None,
        poll: float = DEFAULT_POLL_SECONDS,
    ) -> Json:
        """Wait until a job has ended and return its resource once it ``succeeded``.

        Long-polls ``GET /v1/jobs/{id}?wait=`` (`poll` seconds per request, 1 to 60: the server
        answers at once when the job ends, so `poll` only sets how often `progress` can hear of
        the job's progress). `progress`, if given, is called with the job resource first and then
        whenever its state or iteration counts changed. Raises :class:`JobFailed` (with the job
        and its ``error``) when it ended ``failed`` or ``cancelled``, and :class:`WaitTimeout` (a
        :class:`TimeoutError`) when `timeout` seconds passed first — the job keeps running then.
        """
        return self._wait(f"/v1/jobs/{int(id)}", "job", timeout, progress, poll, JobFailed)

    def _wait(
        self,
        path: str,
        kind: str,
        timeout: Optional[float],
        progress: Optional[Callable[[Json], None]],
        poll: float,
        failed: Union[Type[JobFailed], Type[SweepFailed]],
    ) -> Json:
        """The long-poll loop of :meth:`wait` and :meth:`wait_sweep`."""
        deadline = None if timeout is None else time.monotonic() + timeout
        per_request = max(1, min(MAX_WAIT_SECONDS, math.ceil(poll)))
        resource = self._json("GET", path)
        told: Optional[Tuple[Any, ...]] = None
        while True:
            if progress is not None and _mark(resource) != told:
                told = _mark(resource)
                progress(resource)
            if resource.get("state") in FINAL_STATES:
                break
            seconds = per_request
            if deadline is not None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise WaitTimeout(resource, kind)
                seconds = max(1, min(per_request, math.ceil(remaining)))
            asked = time.monotonic()
            resource = self._json("GET", path, params={"wait": seconds}, timeout=self.timeout + seconds)
            # The server answers a long-poll early only when the resource ended, or when it cannot
            # wait for it (a job waiting in the database for a restart's queue, a shutdown): then
            # pause, so that the loop does not spin.
            quick = time.monotonic() - asked
            if resource.get("state") not in FINAL_STATES and quick < min(1.0, seconds / 2):
                time.sleep(min(1.0, seconds) - quick)
        if resource.get("state") != "succeeded":
            raise failed(resource)
        return resource

    def result(self, id: int, *, lam: Optional[float] = None) -> Json:
        """A job's result document (``GET /v1/jobs/{id}/result``), from its latest checkpoint.

        ``partial`` is true until the job succeeded. Holds ``noise_table`` (one row per strategy),
        ``recommended`` (the row to use, and why), ``weights`` (the recommended table; empty for a
        per-path strategy), ``weights_fit``, ``gain``, ``warnings``, ``references`` (the
        published tables that apply) and, for a job run with ``radii``, ``radii`` (the figures at
        each radius, :meth:`radii`). With `lam`, ``weights`` is the table fitted in-sample on all
        iterations at λ = `lam` (``0``: the paper's procedure) instead; the noise table is the same.
        Raises :class:`ApiError` 409 while the job has no checkpoint yet.
        """
        params = None if lam is None else {"lambda": lam}
        return self._json("GET", f"/v1/jobs/{int(id)}/result", params=params)

    def noise_table(self, id: int) -> pd.DataFrame:
        """A job's noise table as a DataFrame: one row per strategy, in the server's order.

        The columns are the JSON row's fields plus ``paper_luminance``, ``paper_rms_percent`` and
        ``paper_case`` where a published table applies (the paper's Table 1 for the paper's
        configuration); see :func:`optimis_client.noise_table_frame` for a result already fetched.
        """
        return noise_table_frame(self.result(id))

    def radii(self, id: int) -> pd.DataFrame:
        """A job's figures at each radius it tallied (a job run with ``"radii": [R′, …]``) as a
        DataFrame: one row per radius (ascending, the job's own R last) and strategy, with the RMS,
        the bias against the R → 0 reference and their errors, and the radius's merges per
        iteration; see :func:`optimis_client.radii_frame` for the columns and for a result already
        fetched. Empty for a job run without ``radii``."""
        return radii_frame(self.result(id))

    def weights(self, id: int, *, lam: Optional[float] = None) -> pd.DataFrame:
        """A job's weights table as a DataFrame, one row per cell (empty for a per-path
        recommendation): ``cell``, ``r2_lo``, ``r2_hi``, ``r3_lo``, ``r3_hi``,
        ``phi_lo_rad``, ``phi_hi_rad``, ``w0``, ``w0_stderr``, ``w1``, … (docs/csv.md), ``samples``, ``status``. With `lam`,
        the in-sample table at that λ (as :meth:`result`). Only the table: a stack's per-path terms
        and a per-path recommendation are in :meth:`weights_artifact`, their averages per bin in
        :meth:`effective_weights`."""
        return weights_frame(self.result(id, lam=lam).get("weights") or [])

    def weights_artifact(self, id: int, *, strategy: Optional[str] = None) -> Json:
        """A job's weight function as a portable weights artifact (``GET /v1/jobs/{id}/weights``;
        format ``optimis-weights``, version 1): the recommended row's, or `strategy`'s (any row of
        the noise table, e.g. ``"optimal_stacked"``, ``"balance_planes23"``; a fitted row other
        than the recommended one is refitted at its λ). The JSON document as the server sent it —
        ``kind`` (``table``, ``heuristic`` or ``stack``), ``scene``, ``cells`` and ``table``,
        ``heuristics`` with their β and formulas, ``provenance`` and, where the server signs, its
        ``signature`` — ready to be written to a file for ``optimis evaluate --weights`` or a
        renderer (docs/weights-lookup.md); :meth:`weight_function` evaluates it.

        `strategy` must look like a row's name (``^[a-z0-9_]{1,64}$``, else :class:`ValueError`
        before anything is sent); a row the server does not know is an :class:`ApiError` 422 whose
        ``field`` is ``strategy``, a job without a checkpoint yet a 409.
        """
        params = _strategy_params(strategy)
        return self._json(
            "GET", f"/v1/jobs/{int(id)}/weights", params=params or None, timeout=max(self.timeout, _COMPUTE_TIMEOUT)
        )

    def weight_function(self, id: int, *, strategy: Optional[str] = None) -> WeightFunction:
        """A job's weight function ready to evaluate in numpy: :meth:`weights_artifact` checked and
        loaded by :meth:`optimis_client.WeightFunction.load` (``f.weights(**model_path(f, x2,
        x3).inputs())``; see :mod:`optimis_client.weights`). A signing server's ``signature`` is
        kept but not checked here (``optimis evaluate --weights`` checks it)."""
        artifact = self.weights_artifact(id, strategy=strategy)
        return WeightFunction.load(artifact)

    def effective_weights(
        self, id: int, *, strategy: Optional[str] = None, paths: Optional[int] = None
    ) -> pd.DataFrame:
        """A weight function's effective weights per (r2, r3) bin (``GET /v1/jobs/{id}/effective``)
        as a DataFrame, one row per bin (see :func:`optimis_client.effective_weights_frame` for the
        columns; ``frame.attrs`` keeps ``strategy``, ``kind``, ``paths_per_side``,
        ``camera_paths_reaching_plane3`` and ``luminance``). In each bin, ``w0``, ``w1``, ``w2`` are
        the contribution-weighted averages of each technique's weight over the bin's full paths —
        what Fig. 2 shows, for a table, a per-path heuristic or a stack alike — with their sampling
        and fit standard errors; ``NaN`` where no sampled path of the bin carries light.

        Of the recommended row, or of `strategy`'s (as in :meth:`weights_artifact`); `paths` is the
        number of paths each side draws (the server's default 50,000; 1,000 to 1,000,000, the work
        is linear in it). A `strategy` or `paths` out of these bounds raises :class:`ValueError`
        before anything is sent.
        """
        params = _strategy_params(strategy)
        if paths is not None:
            params["paths"] = _effective_paths(paths)
        document = self._json(
            "GET", f"/v1/jobs/{int(id)}/effective", params=params or None, timeout=max(self.timeout, _COMPUTE_TIMEOUT)
        )
        return effective_weights_frame(document)

    def history(self, id: int) -> pd.DataFrame:
        """Each strategy's figures at every checkpoint (``GET /v1/jobs/{id}/history``, at most
        1,000 points) in long format: ``iterations``, ``strategy``, ``luminance``, ``rms_percent``."""
        return history_frame(self._json("GET", f"/v1/jobs/{int(id)}/history"))

    def moments(self, id: int) -> Json:
        """A job's statistics as a checksummed moments document (``GET /v1/jobs/{id}/moments``):
        what :meth:`merge` and :meth:`study` take, and ``optimis report`` reads."""
        return self._json("GET", f"/v1/jobs/{int(id)}/moments", timeout=max(self.timeout, _DOCUMENT_TIMEOUT))

    def merge(self, id: int, source: Union[str, Mapping[str, Any]]) -> Json:
        """Merge statistics into a finished job and return its recomputed result document.

        `source` is a moments document (a dict, e.g. from :meth:`moments`) or the URL of a job on
        a peer server the server was told to trust (``--peer``), sent as ``{"from": URL}``. Runs of
        another configuration, or iterations already counted, are refused (:class:`ApiError` 409).
        """
        return self._json(
            "POST", f"/v1/jobs/{int(id)}/merge", json=_source(source), timeout=max(self.timeout, _DOCUMENT_TIMEOUT)
        )

    def study(
        self, sources: Sequence[Union[str, Mapping[str, Any]]], *, solver: Optional[Mapping[str, Any]] = None
    ) -> Json:
        """Create a finished job from several sources' merged statistics (``POST /v1/studies``).

        Each source is a moments document or a peer job's URL (as in :meth:`merge`); they must
        share one configuration and hold disjoint iterations. `solver` changes solver options from
        the first source's. Returns the study's job resource (its results are computed).
        """
        body: Json = {"sources": [_source(s) for s in sources]}
        if solver is not None:
            body["solver"] = dict(solver)
        return self._json("POST", "/v1/studies", json=body, timeout=max(self.timeout, _DOCUMENT_TIMEOUT))

    def cancel(self, id: int) -> Json:
        """Cancel a queued job, or stop a running one within one chunk of paths; returns the job.

        It keeps the iterations it finished. Raises :class:`ApiError` 409 if it already ended.
        """
        return self._json("POST", f"/v1/jobs/{int(id)}/cancel")

    def delete(self, id: int) -> None:
        """Delete a job that is not running, with its checkpoint (``DELETE /v1/jobs/{id}``)."""
        self.request("DELETE", f"/v1/jobs/{int(id)}")

    def extend(self, id: int, iterations: Optional[int] = None, *, total: Optional[int] = None) -> Json:
        """Add iterations to a job — the same deterministic sequence continues — and return it.

        `iterations` more than it would otherwise reach, or (instead) run until it holds `total`
        (e.g. to resume a cancelled job to its original target). A finished job is queued again.
        """
        if (iterations is None) == (total is None):
            raise ValueError("give exactly one of iterations and total")
        body = {"iterations": iterations} if iterations is not None else {"total": total}
        return self._json("POST", f"/v1/jobs/{int(id)}/extend", json=body)

    # -- predictions ----------------------------------------------------------------------------

    def predict(
        self, id: int, light_paths: int, camera_paths: int, *, solver: Optional[Mapping[str, Any]] = None
    ) -> Json:
        """The noise table at another ray budget (N_F = `light_paths`, N_B = `camera_paths`), with
        the fitted rows re-fitted for it and the row recommended there (``POST
        /v1/jobs/{id}/predict``). Needs a job run with ``"noise_components": true`` (else
        :class:`ApiError` 409). Nothing is run or stored."""
        body: Json = {"light_paths": int(light_paths), "camera_paths": int(camera_paths)}
        if solver is not None:
            body["solver"] = dict(solver)
        return self._json("POST", f"/v1/jobs/{int(id)}/predict", json=body)

    def budget(
        self,
        id: int,
        *,
        target_rms: Optional[float] = None,
        target_rmse: Optional[float] = None,
        light_cost: Optional[float] = None,
        camera_cost: Optional[float] = None,
        iteration_cost: Optional[float] = None,
        merge_cost: Optional[float] = None,
        pixels: float = 1e6,
        solver: Optional[Mapping[str, Any]] = None,
    ) -> Json:
        """The ray budget (N_F, N_B) that reaches `target_rms` (percent) soonest, per strategy
        (``POST /v1/jobs/{id}/budget``), for a renderer costing `light_cost` s per light path,
        `camera_cost` s per camera path and pixel and `iteration_cost` s per iteration, over
        `pixels` pixels. A cost left as None is the server's reference cost (the same that
        ``optimis budget`` and the dashboard take; ``plan["costs"]["source"]`` says which were
        given). Each speed-up over the paper's configuration has a standard error. Needs a job run
        with ``"noise_components": true``.

        With `target_rmse` (percent), the answer also holds ``error_plan``: the plan to a relative
        RMSE about the true pixel value — the noise and the merge radius's bias together — over
        the job's own R and every radius it tallied (a job run with ``"radii": [R′, …]``): the
        fastest (N_F, N_B, R′, strategy) that keeps the fixed weights and that the run supports
        (``best``), the fastest such point at the job's own R (``at_own_radius``), the paper's
        setup (``paper``, when the job tallied R = 0.003), the speed-ups over them with standard
        errors, each (radius, strategy)'s fastest point (``candidates``), the pairs whose bias
        alone reaches the target (``out_of_reach``), a progressive schedule (``progressive``) and
        ``notes``;
        :func:`optimis_client.error_plan_frame` makes a DataFrame of it. `merge_cost` is the
        renderer's seconds per merge event and pixel (t_M; None: the reference's), which makes a
        larger radius cost time. `target_rms` may then be left out: it defaults to `target_rmse`.

        Giving neither target, or a value the server refuses (e.g. a target or cost below 0), is an
        :class:`ApiError` 422 whose ``field`` names it (``target_rms`` when neither was given).
        """
        body: Json = {"pixels": pixels}
        for name, value in (
            ("target_rms", target_rms),
            ("target_rmse", target_rmse),
            ("light_cost", light_cost),
            ("camera_cost", camera_cost),
            ("iteration_cost", iteration_cost),
            ("merge_cost", merge_cost),
        ):
            if value is not None:
                body[name] = value
        if solver is not None:
            body["solver"] = dict(solver)
        return self._json("POST", f"/v1/jobs/{int(id)}/budget", json=body, timeout=max(self.timeout, 120.0))

    def compare(self, ids: Sequence[int]) -> pd.DataFrame:
        """Jobs compared strategy by strategy (``GET /v1/compare``, 2 to 8 ids; the first is the
        baseline), in long format: one row per strategy and run with ``strategy``, ``in_sample``,
        ``run`` (its label), ``run_index``, ``job_id``, ``iterations`` and every figure — L, RMS,
        and against the baseline the L ratio and difference and the RMS ratio, each with its
        ``_stderr``, and ``z``. ``frame.attrs["notes"]`` says how to read them."""
        ids = [int(i) for i in ids]
        document = self._json("GET", "/v1/compare", params={"ids": ",".join(map(str, ids))})
        return compare_frame(document, ids)

    # -- sweeps ---------------------------------------------------------------------------------

    def sweep(
        self,
        doc: Mapping[str, Any],
        *,
        name: Optional[str] = None,
        labels: Optional[Mapping[str, str]] = None,
        notes: Optional[str] = None,
    ) -> Json:
        """Create a sweep (``POST /v1/sweeps``): ``{"base": job document, "axes": [{"field":
        "merge_radius", "values": [...]}, ...], "mode": "grid" | "zip"}``; every run is queued as a
        job. Returns the sweep resource (``id``, ``state``, ``progress``, ``points``). A bad axis
        is an :class:`ApiError` 422 whose ``field`` names it (``axes[1].values[2]``).

        `name`, `labels` (merged over the base's own) and `notes` describe the runs as
        :meth:`submit`'s do a job: they go into the base, so every run carries the labels and is
        named after the name and its swept values (``"R: merge_radius=0.01"``)."""
        document = dict(doc)
        base = dict(document.get("base") or {})
        if name is not None:
            base["name"] = name
        if labels is not None:
            base["labels"] = {**(base.get("labels") or {}), **dict(labels)}
        if notes is not None:
            base["notes"] = notes
        document["base"] = base
        return self._json("POST", "/v1/sweeps", json=document)

    def get_sweep(self, id: int) -> Json:
        """A sweep's resource as it is now (``GET /v1/sweeps/{id}``): progress and, per point, the
        swept values, its job, its noise table and recommended weights."""
        return self._json("GET", f"/v1/sweeps/{int(id)}")

    def wait_sweep(
        self,
        id: int,
        *,
        timeout: Optional[float] = None,
        progress: Optional[Callable[[Json], None]] = None,
        poll: float = DEFAULT_POLL_SECONDS,
    ) -> Json:
        """Wait until every run of a sweep has ended; return the sweep once all succeeded.

        As :meth:`wait`: raises :class:`SweepFailed` (a :class:`JobFailed`) when a run failed or
        was cancelled, :class:`WaitTimeout` when `timeout` seconds passed first.
        """
        return self._wait(f"/v1/sweeps/{int(id)}", "sweep", timeout, progress, poll, SweepFailed)

    def sweep_table(self, id: int) -> pd.DataFrame:
        """A sweep's table as a DataFrame (``GET /v1/sweeps/{id}/table``): one row per point and
        strategy, a column per swept field, as the server's CSV."""
        return sweep_table_frame(self._json("GET", f"/v1/sweeps/{int(id)}/table"))

    def cancel_sweep(self, id: int) -> Json:
        """Cancel every queued or running run of a sweep; returns the sweep."""
        return self._json("POST", f"/v1/sweeps/{int(id)}/cancel")

    def delete_sweep(self, id: int) -> None:
        """Delete a sweep and its jobs (refused, 409, while a run runs: cancel it first)."""
        self.request("DELETE", f"/v1/sweeps/{int(id)}")

    # -- the server -----------------------------------------------------------------------------

    def references(self) -> List[Json]:
        """The published reference tables (``GET /v1/references``): the paper's Table 1, with the
        configuration each applies to and its rows."""
        return list(self._json("GET", "/v1/references").get("references") or [])

    def ready(self) -> bool:
        """Whether the server answers ``/readyz`` with 200 (it can store jobs); ``False`` on 503.

        Raises :class:`ServerUnreachable` when it does not answer at all (:class:`RequestTimeout`
        when not within ``timeout``), :class:`UnexpectedRedirect` on a redirect. Not retried.
        """
        url = self.base_url + "/readyz"
        with Deadline(self.timeout) as deadline:
            response = self._open("GET", url, deadline)
            self._read("GET", url, response, deadline)
        return response.status_code == 200
