"""A real optimis server for the tests: the binary of ``OPTIMIS_BINARY`` (default: the repository's
``target/release/optimis``) on a free loopback port, with a bearer token and a throw-away SQLite
database, started once per session and stopped at its end."""

from __future__ import annotations

import os
import secrets
import socket
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import pytest
import requests

from optimis_client import Client

REPOSITORY = Path(__file__).resolve().parents[3]
DEFAULT_BINARY = REPOSITORY / "target" / "release" / "optimis"
# Seconds for the server to answer /readyz after it started.
STARTUP_SECONDS = 30.0


@dataclass(frozen=True)
class Server:
    """A running test server."""

    url: str
    token: str
    log: Path


def free_port() -> int:
    """A loopback port nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def log_tail(path: Path, lines: int = 30) -> str:
    """The last lines of the server's log, for a failure message."""
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return "(no log)"


@pytest.fixture(scope="session")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """Start the server, wait until /readyz answers 200, and stop it after the session."""
    binary = Path(os.environ.get("OPTIMIS_BINARY") or DEFAULT_BINARY).resolve()
    if not os.access(binary, os.X_OK):
        pytest.exit(f"no optimis binary at {binary} (build it, or set OPTIMIS_BINARY)", returncode=1)
    work = tmp_path_factory.mktemp("optimis-server")
    token = "python-client-" + secrets.token_hex(16)
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    log = work / "server.log"
    environment = {**os.environ, "OPTIMIS_TOKEN": token}
    command = [
        str(binary),
        "serve",
        "--bind",
        f"127.0.0.1:{port}",
        "--database",
        f"sqlite://{work / 'optimis.db'}",
        # Two workers: a test's job never waits behind another test's long one.
        "--workers",
        "2",
    ]
    with open(log, "wb") as log_file:
        process = subprocess.Popen(command, stdout=log_file, stderr=subprocess.STDOUT, env=environment)
    try:
        deadline = time.monotonic() + STARTUP_SECONDS
        while True:
            if process.poll() is not None:
                pytest.exit(f"the server exited with {process.returncode}:\n{log_tail(log)}", returncode=1)
            try:
                if requests.get(url + "/readyz", timeout=2).status_code == 200:
                    break
            except requests.RequestException:
                pass
            if time.monotonic() > deadline:
                pytest.exit(f"the server did not become ready on {url}:\n{log_tail(log)}", returncode=1)
            time.sleep(0.05)
        yield Server(url=url, token=token, log=log)
    finally:
        process.terminate()
        try:
            process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=5)


@pytest.fixture()
def client(server: Server) -> Iterator[Client]:
    """A client of the test server, with its token."""
    with Client(server.url, token=server.token) as c:
        yield c
