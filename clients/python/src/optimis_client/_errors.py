"""The exceptions the client raises: every one is an :class:`OptimisError`."""

from __future__ import annotations

from typing import Any, Dict, Optional

START_HINT = "is the server running? start it with `cargo run --release -- serve` (or `optimis serve`)"


class OptimisError(Exception):
    """Base class of every error this package raises."""


class ServerUnreachable(OptimisError, ConnectionError):
    """No answer from the server: the connection was refused, reset or timed out.

    ``url`` is the server's base URL and ``reason`` what the transport said.
    """

    def __init__(self, url: str, reason: str) -> None:
        """Build the error for the server at ``url`` (its base URL) and the transport's ``reason``."""
        self.url = url
        self.reason = reason
        super().__init__(f"cannot reach the optimis server at {url} ({reason}); {START_HINT}")

    def __reduce__(self) -> Any:
        """Pickle by the constructor's arguments."""
        return (type(self), (self.url, self.reason))


class RequestTimeout(ServerUnreachable, TimeoutError):
    """A request took longer than the client's ``timeout``, which bounds the whole request —
    connecting, sending it and reading the entire answer — not each socket read.

    A :class:`ServerUnreachable` (as a timeout always was) and a built-in :class:`TimeoutError`.
    ``url`` is the server's base URL, ``method`` and ``request_url`` the request, ``seconds`` the
    time it had (a long-poll's waiting time included).
    """

    def __init__(self, url: str, method: str, request_url: str, seconds: float) -> None:
        """Build the error for the server at ``url`` and the request that ran out of time."""
        self.url = url
        self.method = method
        self.request_url = request_url
        self.seconds = seconds
        self.reason = f"no complete answer within {seconds:g} s"
        # Not ServerUnreachable's text: the server may well be running, only too slow.
        super(ServerUnreachable, self).__init__(
            f"{method} {request_url}: {self.reason} (the client's timeout bounds each request as a whole: "
            "connecting, sending it and reading the entire answer; raise it with Client(timeout=...))"
        )

    def __reduce__(self) -> Any:
        """Pickle by the constructor's arguments."""
        return (type(self), (self.url, self.method, self.request_url, self.seconds))


class ResponseTooLarge(OptimisError):
    """An answer was larger than the client's ``max_response_bytes``; it was not read further.

    ``limit`` is the bound, ``size`` the size the answer declared (its ``Content-Length``) or
    ``None`` when it was stopped while streaming, ``method`` and ``url`` the request.
    """

    def __init__(self, limit: int, size: Optional[int], method: str, url: str) -> None:
        """Build the error for the request `method` `url` and the bound `limit` it exceeded."""
        self.limit = limit
        self.size = size
        self.method = method
        self.url = url
        told = f"it declares {size:,} bytes" if size is not None else "it was read up to the bound, no further"
        super().__init__(
            f"{method} {url}: the answer is larger than the client's max_response_bytes of {limit:,} bytes "
            f"({told}); raise the bound with Client(max_response_bytes=...) or client.max_response_bytes = ..."
        )

    def __reduce__(self) -> Any:
        """Pickle by the constructor's arguments."""
        return (type(self), (self.limit, self.size, self.method, self.url))


class UnexpectedRedirect(OptimisError):
    """The server answered with a redirect (3xx), which the client never follows: the request —
    its body and its token — was not sent anywhere else.

    ``status`` is the HTTP status, ``location`` the absolute URL the ``Location`` header names (or
    ``None``), ``method`` and ``url`` the request.
    """

    def __init__(self, status: int, location: Optional[str], method: str, url: str) -> None:
        """Build the error for the request `method` `url` answered `status` towards `location`."""
        self.status = status
        self.location = location
        self.method = method
        self.url = url
        towards = f"a redirect to {location}" if location else "a redirect without a Location"
        super().__init__(
            f"{method} {url}: the server answered {status}, {towards}; the client follows no redirect "
            "(nothing was sent there): give the Client the server's own address"
        )

    def __reduce__(self) -> Any:
        """Pickle by the constructor's arguments."""
        return (type(self), (self.status, self.location, self.method, self.url))


class ApiError(OptimisError):
    """The server answered 4xx or 5xx: an RFC 9457 problem document.

    Attributes: ``status`` (the HTTP status), ``title`` (its summary, e.g. ``Unprocessable
    Entity``), ``detail`` (what went wrong in this request), ``field`` (the JSON path of the
    offending field or parameter on a 422, else ``None``), ``type`` (the problem's type URI),
    ``method`` and ``url`` of the request, and ``problem`` (the whole document, or ``None`` when
    the body was not one). ``str()`` reads ``Title (status): detail [field: name]``.
    """

    def __init__(
        self,
        status: int,
        title: str,
        detail: str,
        field: Optional[str] = None,
        *,
        type: Optional[str] = None,
        method: Optional[str] = None,
        url: Optional[str] = None,
        problem: Optional[Dict[str, Any]] = None,
    ) -> None:
        """Build the error from a problem document's members and the request that got it."""
        self.status = status
        self.title = title
        self.detail = detail
        self.field = field
        self.type = type
        self.method = method
        self.url = url
        self.problem = problem
        super().__init__(status, title, detail, field)

    def __str__(self) -> str:
        """``Title (status): detail``, with `` [field: name]`` when the problem names a field."""
        text = f"{self.title} ({self.status}): {self.detail}"
        if self.field:
            text += f" [field: {self.field}]"
        return text

    def __reduce__(self) -> Any:
        """Pickle by the constructor's arguments and the other members."""
        return (type(self), (self.status, self.title, self.detail, self.field), dict(self.__dict__))

    def __repr__(self) -> str:
        """The constructor call that rebuilds the error's main members."""
        return f"ApiError({self.status!r}, {self.title!r}, {self.detail!r}, {self.field!r})"


class JobFailed(OptimisError):
    """A job waited for ended ``failed`` or ``cancelled``.

    ``job`` is the job resource as it ended, ``state`` its state and ``error`` the server's reason
    (``None`` for a cancelled job, which has none).
    """

    def __init__(self, job: Dict[str, Any], message: Optional[str] = None) -> None:
        """Build the error from the job resource that ended (``message`` overrides the text)."""
        self.job = job
        self.state: str = job.get("state", "unknown")
        self.error: Optional[str] = job.get("error")
        if message is None:
            message = f"job {job.get('id')} {self.state}: {self.error or 'no reason given'}"
        super().__init__(message)

    def __reduce__(self) -> Any:
        """Pickle by the constructor's arguments."""
        return (type(self), (self.job, str(self)))


class SweepFailed(JobFailed):
    """A sweep waited for ended ``failed`` or ``cancelled`` (one of its runs did).

    ``job`` (also ``sweep``) is the sweep resource as it ended; ``failed_runs`` lists its points
    whose run did not succeed (each with ``job_id`` and ``state``).
    """

    def __init__(self, sweep: Dict[str, Any]) -> None:
        """Build the error from the sweep resource that ended."""
        self.sweep = sweep
        self.failed_runs = [p for p in sweep.get("points") or [] if p.get("state") in ("failed", "cancelled")]
        runs = ", ".join(f"job {p.get('job_id')} {p.get('state')}" for p in self.failed_runs[:10])
        more = f" and {len(self.failed_runs) - 10} more" if len(self.failed_runs) > 10 else ""
        reason = f"{runs}{more}" if runs else "no reason given"
        super().__init__(sweep, f"sweep {sweep.get('id')} {sweep.get('state')}: {reason}")

    def __reduce__(self) -> Any:
        """Pickle by the constructor's arguments."""
        return (type(self), (self.sweep,))


class WaitTimeout(OptimisError, TimeoutError):
    """``wait``'s timeout ran out before the job (or sweep) ended; ``last`` is it as last seen.

    A subclass of the built-in :class:`TimeoutError`. The job keeps running: cancel it if it is no
    longer wanted.
    """

    def __init__(self, last: Dict[str, Any], kind: str = "job") -> None:
        """Build the error from the resource as last seen (``kind``: ``job`` or ``sweep``)."""
        self.last = last
        self.state: str = last.get("state", "unknown")
        self.kind = kind
        super().__init__(f"{kind} {last.get('id')} still {self.state} when the timeout ran out")

    def __reduce__(self) -> Any:
        """Pickle by the constructor's arguments."""
        return (type(self), (self.last, self.kind))
