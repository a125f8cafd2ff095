#!/usr/bin/env python3
"""Issue 39's acceptance timings against a real server on loopback (default flags, fresh databases).

    python3 docs/experiments/hardening4.py --optimis target/release/optimis --work /tmp/h4

Starts `optimis serve` on free loopback ports (each server in its own directory under --work) and
measures, in turn:
  1. a plain POST /v1/jobs right after 16 hard-scene submissions whose clients give up after 1 s
     (as `curl -m 1`; every scene a different l3, so no cached quadrature helps);
  2. SIGTERM 50 ms, 5 ms and 0 ms after 10 hard-scene submissions start: time to exit, which
     answers arrived after the signal, and whether every id answered 202 is in the database after
     a restart;
  3. a valid merge from 127.0.0.1 while 127.0.0.2 holds 5 connections, each having sent ~33 MB of
     a 32 MiB merge body and stalled;
  4. fast studies (one source from a fast peer, or one inline document) while studies of 8 sources
     pull from a slow peer (one that sends a space every 100 ms): first two slow studies, then
     (on a fresh server) one slow study with three fast ones after it.
Prints one JSON summary on stdout. Only loopback addresses are contacted.
"""
import argparse
import datetime
import http.client
import json
import os
import select
import signal
import socket
import socketserver
import subprocess
import sys
import threading
import time

SERVERS = []


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def call(port, method, path, body=None, timeout=60, source="127.0.0.1", raw=None):
    """(status, seconds, parsed body or text); raises OSError (socket.timeout included) as it comes."""
    data = raw if raw is not None else (None if body is None else json.dumps(body).encode())
    headers = {"Content-Type": "application/json"} if data is not None else {}
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=timeout, source_address=(source, 0))
    start = time.monotonic()
    try:
        conn.request(method, path, body=data, headers=headers)
        r = conn.getresponse()
        text = r.read()
        status = r.status
    finally:
        conn.close()
    elapsed = time.monotonic() - start
    try:
        return status, elapsed, json.loads(text)
    except ValueError:
        return status, elapsed, text


def hard_scene(l3):
    return {"scene": {"l2": 1e-6, "l3": l3}, "merge_radius": 1e-7}


def small_job(seed):
    return {"engine": "brute", "light_paths": 20000, "camera_paths": 200, "merge_radius": 0.02,
            "iterations": 4, "seed": seed}


class Server:
    def __init__(self, optimis, work, name, extra=(), db=None):
        self.port = free_port()
        self.dir = os.path.join(work, name)
        os.makedirs(self.dir, exist_ok=True)
        self.db = db or os.path.join(self.dir, "optimis.db")
        self.log = open(os.path.join(self.dir, f"server-{self.port}.log"), "w")
        self.proc = subprocess.Popen([optimis, "serve", "--bind", f"127.0.0.1:{self.port}", "--database",
                                      f"sqlite://{self.db}", *extra], stdout=self.log, stderr=self.log)
        SERVERS.append(self)
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"the server {name} exited at start; see {self.log.name}")
            try:
                if call(self.port, "GET", "/healthz", timeout=1)[0] == 200:
                    return
            except OSError:
                pass
            time.sleep(0.05)
        raise RuntimeError(f"the server {name} did not start; see {self.log.name}")

    def stop(self, wait=30):
        """SIGTERM; SIGKILL if it has not exited after `wait` s. Returns seconds to exit (None: killed)."""
        if self.proc.poll() is not None:
            return 0.0
        start = time.monotonic()
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(wait)
            return round(time.monotonic() - start, 3)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            return None

    def wait_succeeded(self, job_id, limit=120):
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline:
            state = call(self.port, "GET", f"/v1/jobs/{job_id}")[2]["state"]
            if state == "succeeded":
                return
            if state in ("failed", "cancelled"):
                raise RuntimeError(f"job {job_id} {state}")
            time.sleep(0.2)
        raise RuntimeError(f"job {job_id} did not finish within {limit} s")

    def finished_job(self, seed):
        status, _, body = call(self.port, "POST", "/v1/jobs", small_job(seed))
        if status != 202:
            raise RuntimeError(f"submission answered {status}: {body}")
        self.wait_succeeded(body["id"])
        return body["id"]

    def moments(self, job_id):
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=60)
        try:
            conn.request("GET", f"/v1/jobs/{job_id}/moments")
            r = conn.getresponse()
            data = r.read()
            if r.status != 200:
                raise RuntimeError(f"moments of {job_id}: {r.status} {data[:300]!r}")
            return data
        finally:
            conn.close()


def outcome(fn):
    """Runs fn() -> (status, seconds, body); returns a dict of status and seconds, or the error."""
    start = time.monotonic()
    try:
        status, took, body = fn()
        d = {"status": status, "seconds": round(took, 3)}
        if status >= 400 and isinstance(body, dict):
            d["detail"] = str(body.get("detail", body))[:200]
        return d
    except socket.timeout:
        return {"status": "abandoned", "seconds": round(time.monotonic() - start, 3)}
    except OSError as e:
        return {"status": f"error: {e}", "seconds": round(time.monotonic() - start, 3)}


# ---------------------------------------------------------------------------------------------
# 1. Sixteen abandoned hard-scene submissions, then a plain one.

def abandoned_hard_scenes(a):
    s = Server(a.optimis, a.work, "1-abandoned")
    results = [None] * 16

    def submit(k):
        results[k] = outcome(lambda: call(s.port, "POST", "/v1/jobs", hard_scene(round(3.101 + 0.001 * k, 3)),
                                          timeout=1))

    threads = [threading.Thread(target=submit, args=(k,)) for k in range(16)]
    for t in threads:
        t.start()
    time.sleep(0.05)
    plain = outcome(lambda: call(s.port, "POST", "/v1/jobs", {"preset": "paper-table1", "iterations": 100,
                                                               "seed": 1}, timeout=30))
    for t in threads:
        t.join()
    stop = s.stop()
    return {"hard_submissions": results,
            "hard_statuses": {st: sum(1 for r in results if str(r["status"]) == st)
                              for st in sorted({str(r["status"]) for r in results})},
            "plain_submission": plain, "plain_within_3s": isinstance(plain["status"], int)
            and plain["status"] == 202 and plain["seconds"] <= 3.0,
            "sigterm_exit_seconds_afterwards": stop}


def utc(stamp):
    """An RFC 3339 UTC time (as in the server's log and job documents) as an aware datetime."""
    stamp = stamp.replace("Z", "+00:00")
    if "." in stamp:
        head, rest = stamp.split(".", 1)
        frac, zone = rest[:rest.index("+")], rest[rest.index("+"):]
        stamp = f"{head}.{frac[:6].ljust(6, '0')}{zone}"
    return datetime.datetime.fromisoformat(stamp)


# ---------------------------------------------------------------------------------------------
# 2. SIGTERM with ten hard-scene submissions in flight.

def sigterm_in_flight(a, delay):
    name = f"2-sigterm-{round(delay * 1000)}ms"
    s = Server(a.optimis, a.work, name)
    answers = [None] * 10
    arrived = [None] * 10

    def submit(k):
        try:
            status, _, body = call(s.port, "POST", "/v1/jobs", hard_scene(round(3.201 + 0.001 * k, 3)), timeout=60)
            answers[k] = {"status": status, "id": body.get("id") if isinstance(body, dict) else None}
        except OSError as e:
            answers[k] = {"status": f"error: {e.__class__.__name__}: {e}", "id": None}
        arrived[k] = time.monotonic()

    threads = [threading.Thread(target=submit, args=(k,)) for k in range(10)]
    t_start = time.monotonic()
    for t in threads:
        t.start()
    time.sleep(delay)
    t_sig = time.monotonic()
    s.proc.send_signal(signal.SIGTERM)
    try:
        s.proc.wait(60)
        exit_seconds = round(time.monotonic() - t_sig, 3)
    except subprocess.TimeoutExpired:
        s.proc.kill()
        s.proc.wait()
        exit_seconds = None
    for t in threads:
        t.join()
    for k in range(10):
        answers[k]["arrived_after_sigterm_s"] = round(arrived[k] - t_sig, 3)
    accepted = [r for r in answers if r["status"] == 202]
    after = [r for r in accepted if r["arrived_after_sigterm_s"] > 0]
    # Restart on the same database: every id answered 202 must have been stored.
    r = Server(a.optimis, a.work, name + "-restart", db=s.db)
    status, _, listing = call(r.port, "GET", "/v1/jobs?limit=500")
    jobs = {j["id"]: j for j in listing["jobs"]} if status == 200 else {}
    stored = set(jobs)
    restart_stop = r.stop(wait=20)
    # When the server began its shutdown (its log), against when each acknowledged job was stored.
    s.log.flush()
    began = None
    with open(s.log.name) as f:
        for line in f:
            if "shutting down" in line:
                began = utc(line.split()[0])
                break
    for k in range(10):
        j = jobs.get(answers[k]["id"])
        if j:
            answers[k]["created_at"] = j["created_at"]
            if began is not None:
                answers[k]["stored_before_shutdown_began"] = utc(j["created_at"]) <= began
    return {"sigterm_after_first_thread_start_s": round(t_sig - t_start, 4),
            "submissions": answers, "exit_seconds_after_sigterm": exit_seconds,
            "answers_arriving_after_sigterm": sum(1 for r in answers if r["arrived_after_sigterm_s"] > 0),
            "exit_within_5s": exit_seconds is not None and exit_seconds <= 5.0,
            "answered_202": len(accepted), "answered_202_arriving_after_sigterm": len(after),
            "stored_after_restart": sorted(stored),
            "shutdown_began_per_server_log": began.isoformat() if began else None,
            "acknowledged_jobs_stored_after_shutdown_began": sum(
                1 for r in accepted if r.get("stored_before_shutdown_began") is False),
            "acknowledged_but_missing_after_restart": sorted(r["id"] for r in accepted if r["id"] not in stored),
            "stored_but_not_acknowledged": sorted(stored - {r["id"] for r in accepted}),
            "restarted_server_sigterm_exit_seconds": restart_stop}


# ---------------------------------------------------------------------------------------------
# 3. Five stalled 32 MiB merge uploads of one client, then another client's valid merge.

def stalled_upload(port, path, send_bytes=33_000_000, length=33_554_432, wait_answer=1.0):
    """Opens a connection from 127.0.0.2, sends the head and `send_bytes` spaces of a `length`-byte body
    (fewer if the server answers or closes first), then waits `wait_answer` s for an answer. Returns the
    socket (left open: the client stalls) and what happened."""
    s = socket.socket()
    s.bind(("127.0.0.2", 0))
    s.connect(("127.0.0.1", port))
    s.sendall((f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json\r\n"
               f"Content-Length: {length}\r\n\r\n").encode())
    s.setblocking(False)
    chunk = b" " * (1 << 20)
    sent, answer, error = 0, b"", None
    start = time.monotonic()
    deadline = start + 20
    answered_at = None
    done_sending_at = None
    while time.monotonic() < deadline:
        writing = sent < send_bytes and not answer and error is None
        if not writing and done_sending_at is None:
            done_sending_at = time.monotonic()
        if not writing and (answer or error or time.monotonic() > done_sending_at + wait_answer):
            break
        timeout = 0.05 if writing else max(0.0, done_sending_at + wait_answer - time.monotonic())
        r, w, _ = select.select([s], [s] if writing else [], [], timeout)
        if r:
            try:
                data = s.recv(65536)
                if data:
                    answer += data
                    answered_at = answered_at or time.monotonic()
                    if b"\r\n\r\n" in answer:
                        break
                else:
                    error = "closed by the server"
            except OSError as e:
                error = f"{e.__class__.__name__}: {e}"
        if w:
            try:
                sent += s.send(chunk[: min(len(chunk), send_bytes - sent)])
            except OSError as e:
                error = f"{e.__class__.__name__}: {e}"
    status = None
    if answer.startswith(b"HTTP/"):
        status = int(answer.split(b" ", 2)[1])
    d = {"bytes_sent": sent, "status": status if status is not None else "no answer",
         "answer_after_s": round(answered_at - start, 3) if answered_at else None}
    if error:
        d["error"] = error
    if status is not None and status >= 400:
        body = answer.split(b"\r\n\r\n", 1)[-1].decode(errors="replace")
        try:
            d["detail"] = json.loads(body).get("detail", "")[:200]
        except ValueError:
            d["detail"] = body[:200]
    return s, d


def stalled_merges(a):
    s = Server(a.optimis, a.work, "3-document-budget")
    first = s.finished_job(21)
    second = s.finished_job(22)
    doc = s.moments(second)
    held, uploads = [], []
    try:
        for _ in range(5):
            sock, d = stalled_upload(s.port, f"/v1/jobs/{first}/merge")
            held.append(sock)
            uploads.append(d)
        merge = outcome(lambda: call(s.port, "POST", f"/v1/jobs/{first}/merge", raw=doc, timeout=60))
    finally:
        for c in held:
            c.close()
    stop = s.stop()
    return {"jobs": [first, second], "document_bytes": len(doc), "stalled_uploads_from_127.0.0.2": uploads,
            "valid_merge_from_127.0.0.1": merge, "sigterm_exit_seconds_afterwards": stop}


# ---------------------------------------------------------------------------------------------
# 4. Studies from a slow peer, and fast studies beside them.

class SlowPeer(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True

    def __init__(self):
        self.stopping = threading.Event()
        self.connections = 0
        super().__init__(("127.0.0.1", 0), SlowHandler)


class SlowHandler(socketserver.BaseRequestHandler):
    def handle(self):
        srv = self.server
        srv.connections += 1
        self.request.settimeout(5)
        head = b""
        try:
            while b"\r\n\r\n" not in head and len(head) < 65536:
                data = self.request.recv(4096)
                if not data:
                    return
                head += data
            self.request.sendall(b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n"
                                 b"Content-Length: 100000\r\n\r\n{")
            while not srv.stopping.wait(0.1):
                self.request.sendall(b" ")
        except OSError:
            pass


def slow_studies(a):
    peer = SlowPeer()
    threading.Thread(target=peer.serve_forever, daemon=True).start()
    slow_port = peer.server_address[1]
    out = {}
    try:
        fast = Server(a.optimis, a.work, "4-fast-peer")
        fast_job = fast.finished_job(31)
        fast_doc = json.loads(fast.moments(fast_job))
        peers = ["--peer", f"http://127.0.0.1:{slow_port}", "--peer", f"http://127.0.0.1:{fast.port}"]
        from_fast = {"sources": [{"from": f"http://127.0.0.1:{fast.port}/v1/jobs/{fast_job}"}]}
        inline = {"sources": [fast_doc]}

        def slow_study(n0):
            return {"sources": [{"from": f"http://127.0.0.1:{slow_port}/v1/jobs/{n}"} for n in range(n0, n0 + 8)]}

        def background(port, body, slot):
            slot.update(outcome(lambda: call(port, "POST", "/v1/studies", body, timeout=200, source="127.0.0.2")))

        # 4a. Two slow 8-source studies from 127.0.0.2; after 0.5 s, fast studies from 127.0.0.1.
        m = Server(a.optimis, a.work, "4a-two-slow-studies", extra=peers)
        slow = [{}, {}]
        for k in range(2):
            threading.Thread(target=background, args=(m.port, slow_study(1 + 8 * k), slow[k]), daemon=True).start()
        time.sleep(0.5)
        out["4a_fast_study_from_peer"] = outcome(lambda: call(m.port, "POST", "/v1/studies", from_fast, timeout=60))
        out["4a_fast_study_inline_document"] = outcome(lambda: call(m.port, "POST", "/v1/studies", inline,
                                                                    timeout=60))
        out["4a_slow_studies_when_fast_done"] = [dict(d) if d else "pending" for d in slow]
        out["4a_slow_peer_connections"] = peer.connections
        out["4a_sigterm_exit_seconds_with_slow_studies"] = m.stop(wait=15)
        time.sleep(0.2)
        out["4a_slow_studies_after_sigterm"] = [dict(d) if d else "pending" for d in slow]

        # 4b. A fresh server: one slow 8-source study from 127.0.0.2, then three fast studies (one after
        # another) from 127.0.0.1.
        before = peer.connections
        m = Server(a.optimis, a.work, "4b-one-slow-study", extra=peers)
        slow1 = {}
        threading.Thread(target=background, args=(m.port, slow_study(101), slow1), daemon=True).start()
        time.sleep(0.5)
        out["4b_fast_studies_from_peer"] = [
            outcome(lambda: call(m.port, "POST", "/v1/studies", from_fast, timeout=60)) for _ in range(3)]
        out["4b_fast_study_inline_document"] = outcome(lambda: call(m.port, "POST", "/v1/studies", inline,
                                                                    timeout=60))
        out["4b_slow_study_when_fast_done"] = dict(slow1) if slow1 else "pending"
        out["4b_slow_peer_connections"] = peer.connections - before
        out["4b_sigterm_exit_seconds_with_slow_study"] = m.stop(wait=15)
        fast.stop()
    finally:
        peer.stopping.set()
        peer.shutdown()
        peer.server_close()
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--optimis", default="target/release/optimis")
    ap.add_argument("--work", required=True)
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    out = {}
    started = time.monotonic()
    try:
        out["1_plain_submit_after_16_abandoned_hard_scenes"] = abandoned_hard_scenes(a)
        # SIGTERM ~50 ms after the submissions start (as briefed), and sooner: a submission is answered
        # in milliseconds now, so at 50 ms none may still be in flight.
        out["2_sigterm_with_10_hard_scenes_in_flight"] = {
            f"sigterm_after_{round(d * 1000)}ms": sigterm_in_flight(a, d) for d in (0.05, 0.005, 0.0)}
        out["3_valid_merge_while_one_client_stalls_5_uploads"] = stalled_merges(a)
        out["4_fast_studies_beside_slow_peer_studies"] = slow_studies(a)
    finally:
        for s in SERVERS:
            if s.proc.poll() is None:
                s.proc.kill()
                s.proc.wait()
        out["total_seconds"] = round(time.monotonic() - started, 1)
        json.dump(out, sys.stdout, indent=1)
        print()


if __name__ == "__main__":
    main()
