"""The viewer under hostile clients (issue 53): compression bombs within the readers' limits,
shutdown by SIGTERM while jobs run, idle and dripping connections, and strict Host parsing.

Servers run in-process (raw sockets, so every byte is under the test's control), or as a
subprocess where the process itself is measured (peak memory, exit status).
"""

from __future__ import annotations

import gzip
import http.client
import json
import os
import re
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest

from spectrageo import io
from spectrageo.geometry import Mesh, PointCloud
from spectrageo.viewer import ViewerServer
from spectrageo.viewer._limits import MIN_BODY_RATE
from spectrageo.viewer.server import TOKEN_HEADER

from conftest import icosphere


# --------------------------------------------------------------------------- helpers
def request(s, method, path, body=None, headers=None, port=None, timeout=30):
    """(status, decoded JSON or bytes) of one request with the session token."""
    h = dict(s.api_headers)
    h.update(headers or {})
    c = http.client.HTTPConnection("127.0.0.1", port or s.port, timeout=timeout)
    try:
        c.request(method, path, body=body, headers=h)
        r = c.getresponse()
        data = r.read()
        ctype = r.headers.get("Content-Type", "")
        return r.status, json.loads(data) if ctype.startswith("application/json") else data
    finally:
        c.close()


def raw(port: int, data: bytes, timeout: float = 10.0) -> bytes:
    """Send raw bytes; everything answered until the server closes or goes quiet."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as c:
        c.sendall(data)
        out = b""
        try:
            while chunk := c.recv(65536):
                out += chunk
                if b"\r\n\r\n" in out and _complete(out):
                    break
        except OSError:
            pass
        return out


def _complete(resp: bytes) -> bool:
    head, _, body = resp.partition(b"\r\n\r\n")
    m = re.search(rb"(?im)^content-length:\s*(\d+)", head)
    return m is not None and len(body) >= int(m.group(1))


def status_of(resp: bytes) -> int:
    assert resp.startswith(b"HTTP/1."), resp[:200]
    return int(resp.split(b" ", 2)[1])


def gzip_bomb(path: Path, n_bytes: int) -> Path:
    """A binary PLY of ``n_bytes`` zero bytes of float32 vertices, gzip-compressed (about 1000:1)
    as repeated 64 MiB members, so that building it takes a fraction of a second."""
    n = n_bytes // 12
    head = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    ).encode()
    block = 64 << 20
    member = gzip.compress(bytes(block), 9)
    full, rest = divmod(n * 12, block)
    data = gzip.compress(head) + member * full + gzip.compress(bytes(rest))
    path.write_bytes(data)
    return path


SERVE = textwrap.dedent(
    """
    import sys, time
    from spectrageo.viewer import ViewerServer
    s = ViewerServer([], port=0).start()
    print(s.port, s.token, flush=True)
    sys.stdin.read()
    s.stop()
    """
)


def peak_rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


# --------------------------------------------------------------------------- compression bombs
@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc (Linux)")
def test_gzip_bomb_upload_refused_quickly_in_bounded_memory(tmp_path):
    bomb = gzip_bomb(tmp_path / "bomb.ply.gz", 1 << 30)  # 1 GiB of vertices in about 1 MB
    assert len(bomb.read_bytes()) < 2 << 20
    p = subprocess.Popen(
        [sys.executable, "-c", SERVE], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        port, token = p.stdout.readline().split()
        before = peak_rss_mb(p.pid)
        c = http.client.HTTPConnection("127.0.0.1", int(port), timeout=60)
        t0 = time.perf_counter()
        c.request("POST", "/api/upload?name=bomb.ply.gz", bomb.read_bytes(), {TOKEN_HEADER: token})
        r = c.getresponse()
        body = json.loads(r.read())
        dt = time.perf_counter() - t0
        peak = peak_rss_mb(p.pid)
        assert r.status == 400, body
        assert "bomb.ply.gz decompresses to more than 512 MB" in body["error"]
        assert "--max-memory of 2048 MB" in body["error"]
        assert dt < 20, dt  # the streamed count takes about 3 s; the full read took minutes
        assert peak - before < 300, (before, peak)  # it peaked at 6.8 GB
        c.request("GET", "/api/state", headers={TOKEN_HEADER: token})
        assert c.getresponse().status == 200
        c.close()
    finally:
        p.stdin.close()
        p.wait(timeout=30)


def test_upload_readers_apply_the_viewers_memory_cap(tmp_path):
    V = np.random.default_rng(0).random((50_000, 3))
    io.write(tmp_path / "cloud.ply", PointCloud(V))
    data = (tmp_path / "cloud.ply").read_bytes()  # about 0.6 MB; its reader asks for more
    with ViewerServer([], port=0, max_memory_mb=2).start() as s:  # 0.5 MB per upload
        st, r = request(s, "POST", "/api/upload?name=cloud.ply", data)
        assert st == 400, r
        assert re.search(
            r"more than the memory cap of 512\.0 KiB \(a quarter of the viewer's "
            r"--max-memory of 2 MB\)",
            r["error"],
        ), r["error"]
        assert "SPECTRAGEO_MAX_BYTES" not in r["error"]
        np.savez_compressed(tmp_path / "zeros.npz", vertices=np.zeros((1, 50_000, 3)))
        st, r = request(s, "POST", "/api/upload?name=z.npz", (tmp_path / "zeros.npz").read_bytes())
        assert st == 400 and "z.npz decompresses to more than 0.5 MB, a quarter" in r["error"]
    with ViewerServer([], port=0).start() as s:  # the default budget reads it
        st, r = request(s, "POST", "/api/upload?name=cloud.ply", data)
        assert st == 200 and r["model"]["n_vertices"] == 50_000
    assert len(io.read(tmp_path / "cloud.ply").points) == 50_000  # the cap stays in the viewer


# --------------------------------------------------------------------------- SIGTERM with jobs
def _start_cli(tmp_path, mesh: Path, prelude: str = ""):
    env = dict(os.environ, TMPDIR=str(tmp_path), PYTHONUNBUFFERED="1")
    code = prelude + (
        "import sys; from spectrageo.cli.main import main; "
        f"sys.exit(main(['view', '--port', '0', '--no-browser', {str(mesh)!r}]))"
    )
    p = subprocess.Popen([sys.executable, "-c", code], env=env, stderr=subprocess.PIPE, text=True)
    line = ""
    for _ in range(50):
        line = p.stderr.readline()
        if "spectrageo viewer on" in line or not line:
            break
    m = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
    assert m, line
    port = int(m.group(1))
    page = raw(port, b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
    token = re.search(rb'name="spectrageo-token" content="([^"]+)"', page).group(1).decode()
    return p, port, token


def _call(port: int, token: str, method: str, path: str, body=None) -> tuple[int, dict]:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    try:
        c.request(method, path, None if body is None else json.dumps(body), {TOKEN_HEADER: token})
        r = c.getresponse()
        return r.status, json.loads(r.read())
    finally:
        c.close()


STUCK_JOBS = textwrap.dedent(
    """
    import time
    from spectrageo.viewer import _session

    def spin(self, m, patch, frame, job=None):
        try:
            import torch
        except ImportError:
            job.update(0.5, "spinning")
            time.sleep(300)
        a = torch.randn(1500, 1500)
        job.update(0.5, "spinning")
        while True:
            a @ a

    _session.ViewerSession.features = spin
    """
)


@pytest.mark.parametrize("stuck", [False, True], ids=["library-jobs", "uncancellable-jobs"])
def test_sigterm_with_ten_jobs_exits_cleanly(tmp_path, stuck):
    mesh = tmp_path / "sphere.ply"
    io.write(mesh, Mesh(*icosphere(4)))
    # uncancellable: each job spins in native code that never reports progress (torch's thread
    # pool where installed: a process exiting under it aborts with "terminate called ...")
    prelude = STUCK_JOBS if stuck else ""
    p, port, token = _start_cli(tmp_path, mesh, prelude)
    try:
        routes = [
            ("/api/model/m1/denoise", {"method": "tsgsp"}),
            ("/api/model/m1/features", {"patch": 15}),
            ("/api/model/m1/outliers", {"method": "rpca", "k": 10}),
            ("/api/model/m1/scalar", {"field": "saliency"}),
        ]
        answers = [_call(port, token, "POST", *routes[k % len(routes)]) for k in range(10)]
        assert [st for st, _ in answers] == [200] * 10  # 2 running, 8 queued
        dirs = list(tmp_path.glob(f"spectrageo-view-{p.pid}-*"))
        time.sleep(0.5)
        t0 = time.perf_counter()
        while stuck and time.perf_counter() - t0 < 60:  # until a job spins in native code
            job = _call(port, token, "GET", f"/api/job/{answers[1][1]['job']}")[1]
            if job["message"] == "spinning":
                break
            time.sleep(0.1)
        t0 = time.perf_counter()
        p.send_signal(signal.SIGTERM)
        rc = p.wait(timeout=60)
        err = p.stderr.read()
        assert rc == 0, (rc, err)  # it once died of SIGABRT (-6)
        assert "terminate called" not in err and "Traceback" not in err, err
        assert time.perf_counter() - t0 < 30
        if stuck:
            assert "stopped while a computation was running" in err
        assert len(dirs) == 1 and not dirs[0].exists()
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


def test_stop_cancels_queued_jobs_and_reports_stuck_ones():
    with ViewerServer([], port=0, max_jobs=1, max_queued=3) as s:
        gate = threading.Event()
        running = s.session.start("slow", lambda job: gate.wait(30))
        t0 = time.perf_counter()
        while running.queued and time.perf_counter() - t0 < 10:  # a worker has picked it up
            time.sleep(0.01)
        assert not running.queued
        queued = [s.session.start("later", lambda job: {"ran": True}) for _ in range(3)]
        t0 = time.perf_counter()
        assert s.stop(timeout=0.5) is False  # the running job ignores cancellation
        assert time.perf_counter() - t0 < 5
        gate.set()
        t0 = time.perf_counter()
        while running.finished is None and time.perf_counter() - t0 < 10:
            time.sleep(0.02)
        for j in queued:
            t1 = time.perf_counter()
            while j.finished is None and time.perf_counter() - t1 < 10:
                time.sleep(0.02)
            assert j.state == "error" and "cancelled, the viewer is stopping" in j.error
            assert j.result is None
    with ViewerServer([], port=0) as s:  # a job that reports progress stops at its next report
        job = s.session.start("progress", _report_progress)
        time.sleep(0.2)
        assert s.stop(timeout=10) is True
        assert job.state == "error" and "progress: cancelled" in job.error


def _report_progress(job):
    for k in range(1000):
        job.update(k / 1000, "working")
        time.sleep(0.01)
    return {"ran": True}


# --------------------------------------------------------------------------- connections
def test_idle_connections_do_not_block_other_requests():
    with ViewerServer([], port=0).start() as s:  # 64 connections, 30 s request timeout
        idle = [socket.create_connection(("127.0.0.1", s.port)) for _ in range(80)]
        try:
            time.sleep(1.5)  # they have waited longer than the grace period
            for _ in range(5):
                t0 = time.perf_counter()
                st, r = request(s, "GET", "/api/state", timeout=10)
                assert st == 200 and "models" in r
                assert time.perf_counter() - t0 < 5  # not the 30 s request timeout
            assert s.httpd.active_connections <= s.limits.max_connections + 5
        finally:
            for c in idle:
                c.close()


def test_dripped_body_has_a_total_deadline():
    with ViewerServer([], port=0, request_timeout=1.0).start() as s:
        n = 40
        assert n / MIN_BODY_RATE < 0.01
        with socket.create_connection(("127.0.0.1", s.port), timeout=10) as c:
            c.sendall(
                (
                    "POST /api/upload?name=d.off HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                    f"{TOKEN_HEADER}: {s.token}\r\nContent-Length: {n}\r\n\r\n"
                ).encode()
            )
            t0 = time.perf_counter()
            out = b""
            c.settimeout(0.3)
            for _ in range(n):  # one byte every 0.3 s: every pause is below the timeout
                try:
                    c.sendall(b"x")
                except OSError:
                    break
                try:
                    out += c.recv(65536)
                except TimeoutError:
                    continue
                except OSError:
                    break
                if b"\r\n\r\n" in out:
                    break
            dt = time.perf_counter() - t0
            c.settimeout(5)  # the body may follow the headers in a later segment
            while True:
                try:
                    more = c.recv(65536)
                except OSError:
                    break
                if not more:  # the server closes the connection after its 408
                    break
                out += more
        assert status_of(out) == 408, out[:300]
        assert b"request body not received in time" in out
        assert dt < 4, dt  # 1 s + 40 bytes at 256 KiB/s, not 40 x 0.3 s
        time.sleep(0.1)
        assert not list(s.tmp_dir.iterdir())
        assert request(s, "GET", "/api/state")[0] == 200


# --------------------------------------------------------------------------- Host and target
@pytest.mark.parametrize(
    "head, want",
    [
        ("GET /api/state HTTP/1.1\r\nHost: 127.0.0.1:{port}@evil.example\r\n", 400),
        ("GET /api/state HTTP/1.1\r\nHost: evil.example@127.0.0.1:{port}\r\n", 400),
        ("GET /api/state HTTP/1.1\r\nHost: 127.0.0.1:{port}/x\r\n", 400),
        ("GET /api/state HTTP/1.1\r\nHost: 127.0.0.1:99999\r\n", 400),
        ("GET /api/state HTTP/1.1\r\nHost: 127.0.0.1 evil.example\r\n", 400),
        ("GET /api/state HTTP/1.1\r\nHost: [::1\r\n", 400),
        ("GET /api/state HTTP/1.1\r\nHost: 127.0.0.1\r\nHost: evil.example\r\n", 400),
        ("GET /api/state HTTP/1.1\r\nHost: 127.0.0.1\r\nhost: 127.0.0.1\r\n", 400),
        ("GET /api/state HTTP/1.1\r\n", 400),
        ("GET http://127.0.0.1:{port}/api/state HTTP/1.1\r\nHost: 127.0.0.1\r\n", 400),
        ("GET http://evil.example/api/state HTTP/1.1\r\nHost: 127.0.0.1\r\n", 400),
        ("GET / HTTP/1.1\r\nHost: evil.example:{port}\r\n", 403),
        ("GET / HTTP/1.1\r\nHost: 127.0.0.2\r\n", 403),
        ("GET / HTTP/1.1\r\nHost: localhost.\r\n", 403),
        ("GET / HTTP/1.1\r\nHost: [::2]:{port}\r\n", 403),
    ],
)
def test_host_is_parsed_strictly(head, want):
    with ViewerServer([], port=0).start() as s:
        text = head.format(port=s.port) + f"{TOKEN_HEADER}: {s.token}\r\nConnection: close\r\n\r\n"
        resp = raw(s.port, text.encode())
        assert status_of(resp) == want, resp[:300]
        assert b'"models"' not in resp and b"spectrageo-token" not in resp


@pytest.mark.parametrize(
    "host",
    [
        "127.0.0.1",
        "127.0.0.1:{port}",
        "localhost:{port}",
        "LocalHost",
        "[::1]:{port}",
        "[0:0:0:0:0:0:0:1]",
    ],
)
def test_loopback_hosts_still_served(host):
    with ViewerServer([], port=0).start() as s:
        text = (
            f"GET /api/state HTTP/1.1\r\nHost: {host.format(port=s.port)}\r\n"
            f"{TOKEN_HEADER}: {s.token}\r\nConnection: close\r\n\r\n"
        )
        resp = raw(s.port, text.encode())
        assert status_of(resp) == 200 and b'"models"' in resp
        # HTTP/1.0 may leave Host out; a path starting with // is a path, never a host
        resp = raw(s.port, f"GET /api/state HTTP/1.0\r\n{TOKEN_HEADER}: {s.token}\r\n\r\n".encode())
        assert status_of(resp) == 200
        st, _ = request(s, "GET", "//evil.example/api/state")
        assert st == 404


def test_upload_names_still_quoted(tmp_path):
    io.write(tmp_path / "s.off", Mesh(*icosphere(1)))
    with ViewerServer([], port=0).start() as s:
        st, r = request(
            s, "POST", "/api/upload?name=" + quote("a b?.off"), (tmp_path / "s.off").read_bytes()
        )
        assert st == 200 and r["model"]["name"] == "a b?.off"
