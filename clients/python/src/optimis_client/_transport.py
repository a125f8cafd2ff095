"""The client's transport: a deadline over each whole request, not over each socket operation.

requests' (urllib3's) timeouts bound each connect, send and read on the socket: a server that
trickles its answer a byte at a time never trips one. A :class:`Deadline` bounds the whole
request instead: when it passes, a timer thread shuts down the socket of the connection the
request runs on, which ends whatever connect, send or read is blocked on it.

The socket a request runs on is known in two ways: the connections of the pools of a
:class:`WatchedAdapter` (mounted on the sessions the client creates) report theirs to the
deadline of their thread's request as they connect and send, so connecting, sending and waiting
for the headers are bounded as well as the body; and, on another session, the client has the
deadline watch the answer once its headers arrived (:meth:`Deadline.watch_answer`), which bounds
reading the body.
"""

from __future__ import annotations

import socket
import threading
import time
from typing import TYPE_CHECKING, Any, Callable, Dict, Optional, Type

from requests.adapters import HTTPAdapter
from urllib3 import poolmanager
from urllib3.connection import HTTPConnection, HTTPSConnection
from urllib3.connectionpool import HTTPConnectionPool, HTTPSConnectionPool

# The deadline of the request this thread is sending, if any.
_current = threading.local()


def _shutter(sock: Any) -> Optional[Callable[[], None]]:
    """What shuts `sock` (a connection's socket) down both ways, ending any operation blocked on
    it; ``None`` for no socket."""
    if sock is not None and not isinstance(sock, socket.socket):
        sock = getattr(sock, "socket", None)  # TLS within TLS (through an HTTPS proxy)
    if not isinstance(sock, socket.socket):
        return None
    plain: socket.socket = sock

    def shut() -> None:
        # socket.socket's own shutdown, also for a TLS socket: unlike SSLSocket.shutdown, it leaves
        # the TLS state alone for the thread that is reading.
        socket.socket.shutdown(plain, socket.SHUT_RDWR)

    return shut


def _stop(stop: Callable[[], None]) -> None:
    """Call `stop`, whose socket may be closed or not connected any more."""
    try:
        stop()
    except (OSError, ValueError, RuntimeError):
        pass  # closed, not connected, or already back in its pool: nothing to end


class Deadline:
    """The time one request may take in all; a context manager around sending it and reading
    its answer, on one thread. ``passed`` tells whether the timer went off (and stopped the
    request's socket, if it was watching one)."""

    def __init__(self, seconds: float) -> None:
        """A deadline `seconds` from now (its timer starts on entering)."""
        self.seconds = seconds
        self.end = time.monotonic() + seconds
        self.passed = False
        self._lock = threading.Lock()
        self._stop: Optional[Callable[[], None]] = None
        self._over = False
        self._timer = threading.Timer(max(0.0, seconds), self._expire)
        self._timer.daemon = True

    def __enter__(self) -> "Deadline":
        """Start the timer; the requests this thread sends from now on run under this deadline."""
        _current.deadline = self
        self._timer.start()
        return self

    def __exit__(self, *exc: object) -> None:
        """Stop the timer and forget the socket (its connection may serve other requests now)."""
        with self._lock:
            self._over = True
            self._timer.cancel()
            self._stop = None
        _current.deadline = None

    def remaining(self) -> float:
        """Seconds left (negative once the deadline passed)."""
        return self.end - time.monotonic()

    def expired(self) -> bool:
        """Whether the deadline passed."""
        return self.passed or self.remaining() <= 0

    @property
    def watching(self) -> bool:
        """Whether the deadline has a socket to stop."""
        return self._stop is not None

    def watch(self, stop: Callable[[], None]) -> None:
        """Call `stop` (which shuts the request's socket down) when the deadline passes — at
        once if it passed already."""
        with self._lock:
            if self._over:
                return
            self._stop = stop
            if self.passed:
                _stop(stop)

    def watch_answer(self, raw: Any) -> None:
        """Unless a socket is watched already, watch the one the body of `raw` (a urllib3
        ``HTTPResponse``) comes on: through its ``shutdown`` (urllib3 2.3 and later), else its
        connection's socket — which an older urllib3 no longer holds when the answer ends with the
        connection's close: such a body is then bounded only between chunks and by the timeout of
        each read."""
        if self.watching:
            return
        shutdown = getattr(raw, "shutdown", None)
        stop = shutdown if callable(shutdown) else _shutter(getattr(getattr(raw, "connection", None), "sock", None))
        if stop is not None:
            self.watch(stop)

    def _expire(self) -> None:
        """The timer went off: stop the watched socket."""
        with self._lock:
            if self._over:
                return
            self.passed = True
            if self._stop is not None:
                _stop(self._stop)


def _watch(sock: Any) -> None:
    """Have the deadline of this thread's request, if any, watch `sock`."""
    deadline: Optional[Deadline] = getattr(_current, "deadline", None)
    shut = _shutter(sock)
    if deadline is not None and shut is not None:
        deadline.watch(shut)


if TYPE_CHECKING:
    _Connection = HTTPConnection
else:
    _Connection = object


class _Watched(_Connection):
    """A connection mix-in: the deadline of the request being sent watches the connection's
    socket once it is connected (a new one) and as the request starts (one kept alive). The
    socket itself, not the connection: http.client drops the connection's ``sock`` when it hands
    the socket to an answer that ends with the connection's close."""

    def connect(self) -> None:
        """Connect, then report to the deadline (which shuts the socket at once if it passed)."""
        super().connect()
        _watch(self.sock)

    def request(self, *args: Any, **kwargs: Any) -> None:
        """Report to the deadline (a kept-alive connection has its socket already), then send."""
        _watch(self.sock)
        super().request(*args, **kwargs)


class _WatchedHTTPConnection(_Watched, HTTPConnection):
    """An HTTP connection a deadline watches."""


class _WatchedHTTPSConnection(_Watched, HTTPSConnection):
    """An HTTPS connection a deadline watches."""


class _WatchedHTTPPool(HTTPConnectionPool):
    """A pool of watched HTTP connections."""

    ConnectionCls = _WatchedHTTPConnection


class _WatchedHTTPSPool(HTTPSConnectionPool):
    """A pool of watched HTTPS connections."""

    ConnectionCls = _WatchedHTTPSConnection


_WATCHED_POOLS: Dict[str, Type[HTTPConnectionPool]] = {"http": _WatchedHTTPPool, "https": _WatchedHTTPSPool}


def _use_watched_pools(manager: Any) -> None:
    """Make a urllib3 pool manager (or HTTP proxy manager) open watched pools; a manager with
    pools of its own (SOCKS) keeps them, and only the body of an answer is bounded then."""
    if getattr(manager, "pool_classes_by_scheme", None) is poolmanager.pool_classes_by_scheme:
        manager.pool_classes_by_scheme = _WATCHED_POOLS


class WatchedAdapter(HTTPAdapter):
    """requests' adapter, with connections a :class:`Deadline` watches from connect to answer."""

    def init_poolmanager(self, *args: Any, **kwargs: Any) -> None:
        """requests' pool manager, opening watched pools."""
        super().init_poolmanager(*args, **kwargs)
        _use_watched_pools(self.poolmanager)

    def proxy_manager_for(self, proxy: str, **proxy_kwargs: Any) -> Any:
        """requests' proxy manager, opening watched pools."""
        manager = super().proxy_manager_for(proxy, **proxy_kwargs)
        _use_watched_pools(manager)
        return manager
