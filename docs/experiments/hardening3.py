#!/usr/bin/env python3
"""Issue 22's acceptance timings against a real server on loopback (default flags, fresh database).

    python3 docs/experiments/hardening3.py --optimis target/release/optimis --work /tmp/h3

Starts `optimis serve` on a free loopback port and measures, in turn:
  1. a plain POST /v1/jobs after two abandoned 256-point sweep creations (clients that go away
     after 2 s, as `curl -m 2`);
  2. the creation time of a 256-point default-scene sweep (one quadrature for its scene);
  3. a plain POST /v1/jobs while four clients read a 256-point predicted sweep;
  4. a third study request while two clients trickle study bodies (1 byte / 2 s);
  5. GET /healthz from 127.0.0.2 while 127.0.0.1 holds 600 half-open connections;
  6. how long SIGTERM takes to stop the server during a sweep creation, and what it acknowledged.
Prints one JSON summary on stdout. Only loopback addresses are contacted.
"""
import argparse
import json
import os
import signal
import socket
import subprocess
import threading
import time
import urllib.error
import urllib.request


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def request(base, method, path, body=None, timeout=60, source=None):
    """(status, seconds, parsed body or text)."""
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(base + path, data=data, method=method)
    if data is not None:
        req.add_header("Content-Type", "application/json")
    start = time.monotonic()
    try:
        if source:
            host, port = base.split("//")[1].split(":")
            conn = socket.create_connection((host, int(port)), timeout=timeout, source_address=(source, 0))
            head = f"{method} {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n"
            conn.sendall(head.encode())
            out = b""
            while chunk := conn.recv(65536):
                out += chunk
            conn.close()
            status = int(out.split(b" ", 2)[1])
            return status, time.monotonic() - start, out.split(b"\r\n\r\n", 1)[-1].decode(errors="replace")
        with urllib.request.urlopen(req, timeout=timeout) as r:
            text = r.read().decode()
            status = r.status
    except urllib.error.HTTPError as e:
        text, status = e.read().decode(), e.code
    elapsed = time.monotonic() - start
    try:
        return status, elapsed, json.loads(text)
    except ValueError:
        return status, elapsed, text


def raw_post(port, path, body, hold, stop_after=None):
    """Sends a POST with the whole body, then waits `hold` seconds and closes (a client going away)."""
    s = socket.create_connection(("127.0.0.1", port))
    data = json.dumps(body).encode()
    head = (f"POST {path} HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\n"
            f"Content-Length: {len(data)}\r\n\r\n").encode()
    s.sendall(head + data)
    time.sleep(hold)
    s.close()


def sweep(points, seed0=1):
    return {"base": {"iterations": 1, "light_paths": 1000},
            "axes": [{"field": "seed", "values": list(range(seed0, seed0 + points))}]}


def job(seed):
    return {"iterations": 1, "light_paths": 1000, "seed": seed}


class Server:
    def __init__(self, optimis, work, extra=()):
        self.port = free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        db = os.path.join(work, f"o-{self.port}.db")
        self.log = open(os.path.join(work, f"server-{self.port}.log"), "w")
        self.proc = subprocess.Popen([optimis, "serve", "--bind", f"127.0.0.1:{self.port}", "--database",
                                      f"sqlite://{db}", *extra], stdout=self.log, stderr=self.log)
        for _ in range(200):
            try:
                if request(self.base, "GET", "/healthz", timeout=1)[0] == 200:
                    return
            except OSError:
                time.sleep(0.05)
        raise RuntimeError("the server did not start")

    def stop(self):
        self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(30)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--optimis", default="target/release/optimis")
    ap.add_argument("--work", required=True)
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    out = {}

    # 1. Two abandoned sweep creations, then a plain submission.
    s = Server(a.optimis, a.work)
    threads = [threading.Thread(target=raw_post, args=(s.port, "/v1/sweeps", sweep(256, 1 + 1000 * k), 2.0))
               for k in range(2)]
    for t in threads:
        t.start()
    time.sleep(0.3)
    status, took, _ = request(s.base, "POST", "/v1/jobs", job(7))
    out["submit_after_two_abandoned_sweeps"] = {"status": status, "seconds": round(took, 3)}
    for t in threads:
        t.join()
    # 2. A 256-point default-scene sweep, created (its scene's quadrature may be cached by now: a
    # fresh server measures the uncached case).
    s.stop()
    s = Server(a.optimis, a.work)
    status, took, body = request(s.base, "POST", "/v1/sweeps", sweep(256))
    out["create_256_point_sweep_fresh_server"] = {"status": status, "seconds": round(took, 3)}
    s.stop()

    # 3. Four readers of a 256-point predicted sweep, then a submission.
    s = Server(a.optimis, a.work)
    predicted = {"base": {"preset": "paper-table1", "iterations": 400, "noise_components": True},
                 "axes": [{"field": "seed", "values": list(range(1, 17))},
                          {"field": "light_paths", "by": "prediction",
                           "values": [2_000_000 * (k + 1) for k in range(16)]}]}
    status, _, body = request(s.base, "POST", "/v1/sweeps", predicted)
    sid = body["id"] if status == 201 else None
    out["predicted_sweep"] = {"status": status, "points": len(body.get("points", [])) if sid else body}
    if sid:
        while request(s.base, "GET", f"/v1/sweeps/{sid}")[2]["state"] not in ("succeeded", "failed"):
            time.sleep(1)
        stop = threading.Event()
        reads = []

        def reader():
            while not stop.is_set():
                st, t, _ = request(s.base, "GET", f"/v1/sweeps/{sid}", timeout=120)
                reads.append((st, t))

        readers = [threading.Thread(target=reader) for _ in range(4)]
        for t in readers:
            t.start()
        time.sleep(1.0)
        status, took, _ = request(s.base, "POST", "/v1/jobs", job(8))
        out["submit_while_four_read_a_predicted_sweep"] = {"status": status, "seconds": round(took, 3)}
        stop.set()
        for t in readers:
            t.join()
        out["predicted_sweep_reads"] = {"count": len(reads), "statuses": sorted({r[0] for r in reads}),
                                        "max_seconds": round(max(r[1] for r in reads), 3)}
    s.stop()

    # 4. Two trickling study bodies, then a third study.
    s = Server(a.optimis, a.work)
    trick = []
    for _ in range(2):
        c = socket.create_connection(("127.0.0.1", s.port))
        c.sendall(b"POST /v1/studies HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\n"
                  b"Content-Length: 100000\r\n\r\n{")
        trick.append(c)
    stop = threading.Event()

    def trickle():
        while not stop.is_set():
            for c in trick:
                try:
                    c.sendall(b" ")
                except OSError:
                    pass
            stop.wait(2)

    tt = threading.Thread(target=trickle)
    tt.start()
    time.sleep(1)
    status, took, body = request(s.base, "POST", "/v1/studies", {"sources": []})
    out["third_study_while_two_trickle"] = {"status": status, "seconds": round(took, 3)}
    stop.set()
    tt.join()
    for c in trick:
        c.close()

    # 5. 600 half-open connections from 127.0.0.1, /healthz from 127.0.0.2.
    held = []
    refused = 0
    for _ in range(600):
        try:
            c = socket.create_connection(("127.0.0.1", s.port), timeout=2)
            c.sendall(b"GET /healthz HTTP/1.1\r\n")
            held.append(c)
        except OSError:
            refused += 1
    time.sleep(0.5)
    status, took, _ = request(s.base, "GET", "/healthz", timeout=30, source="127.0.0.2")
    out["healthz_from_another_client_during_600_half_open"] = {"status": status, "seconds": round(took, 3),
                                                               "connect_errors": refused}
    for c in held:
        c.close()
    s.stop()

    # 6. SIGTERM during a sweep creation.
    s = Server(a.optimis, a.work)
    t = threading.Thread(target=lambda: out.setdefault("sweep_during_sigterm", request(
        s.base, "POST", "/v1/sweeps", sweep(256, 5000), timeout=30)[:2]))
    t.start()
    time.sleep(0.2)
    start = time.monotonic()
    s.proc.send_signal(signal.SIGTERM)
    s.proc.wait(60)
    out["sigterm_exit_seconds"] = round(time.monotonic() - start, 3)
    t.join()
    json.dump(out, __import__("sys").stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
