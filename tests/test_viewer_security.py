"""Hostile input against the viewer server: cross-origin requests, hostile names, oversized bodies,
resource limits, timeouts and temporary files.

Plain HTTP against a server started in-process (``http.client`` and raw sockets, so that every
header is under the test's control); the script-injection and CSP cases run in headless Chromium
(skipped when Playwright or ``/usr/bin/chromium`` is missing).
"""

from __future__ import annotations

import gzip
import http.client
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import unicodedata
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest

from spectrageo import io
from spectrageo._errors import InvalidInputError
from spectrageo.geometry import Mesh
from spectrageo.viewer import ViewerServer, ViewerSession
from spectrageo.viewer.server import (
    TOKEN_HEADER,
    ViewerLimits,
    clean_name,
    content_disposition,
    remove_stale_temp_dirs,
)

from conftest import cube, require_module, skip_or_fail

EVIL = "http://evil.example"


# --------------------------------------------------------------------------- helpers
@pytest.fixture(scope="module")
def cube_off(tmp_path_factory) -> bytes:
    p = tmp_path_factory.mktemp("sec") / "c.off"
    io.write(p, Mesh(*cube(3)))
    return p.read_bytes()


@pytest.fixture
def srv():
    s = ViewerServer([], port=0).start()
    yield s
    s.stop()


def request(s, method, path, body=None, headers=None, token=True, timeout=30):
    """(status, headers, body bytes) of one request on a fresh connection."""
    h = dict(s.api_headers) if token else {}
    h.update(headers or {})
    c = http.client.HTTPConnection("127.0.0.1", s.port, timeout=timeout)
    try:
        c.request(method, path, body=body, headers=h)
        r = c.getresponse()
        return r.status, r.headers, r.read()
    finally:
        c.close()


def jrequest(s, method, path, body=None, headers=None, token=True):
    st, h, data = request(s, method, path, body, headers, token)
    return st, json.loads(data or b"{}")


def upload(s, name, data, **kw):
    return jrequest(s, "POST", "/api/upload?name=" + quote(name, safe=""), data, **kw)


def raw_exchange(s, head: bytes, body: bytes = b"", timeout=10.0) -> bytes:
    """Send raw bytes, return everything the server answers until it closes or goes quiet."""
    with socket.create_connection(("127.0.0.1", s.port), timeout=timeout) as c:
        c.sendall(head)
        if body:
            try:
                c.sendall(body)
            except OSError:
                pass
        out = b""
        try:
            while b"\r\n\r\n" not in out or len(out) < out.index(b"\r\n\r\n") + 4 + _clen(out):
                chunk = c.recv(65536)
                if not chunk:
                    break
                out += chunk
        except OSError:
            pass
        return out


def _clen(resp: bytes) -> int:
    for line in resp.split(b"\r\n\r\n", 1)[0].split(b"\r\n"):
        if line.lower().startswith(b"content-length:"):
            return int(line.split(b":", 1)[1])
    return 0


def rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def n_models(s) -> int:
    return len(s.session.models)


# --------------------------------------------------------------------------- origin, token, CSRF
def test_cross_origin_posts_refused_without_side_effect(srv, cube_off):
    assert upload(srv, "ok.off", cube_off)[0] == 200
    before_models, before_jobs = n_models(srv), len(srv.session.jobs)
    port = srv.port
    refusals = [
        {"Origin": EVIL},  # another site, even with the token
        {"Origin": "null"},  # sandboxed frames, file:// pages
        {"Origin": f"http://127.0.0.1:{port + 1}"},  # another local port (same site)
        {"Origin": f"https://127.0.0.1:{port}"},
        {"Sec-Fetch-Site": "cross-site"},
        {"Sec-Fetch-Site": "same-site"},
    ]
    for hdr in refusals:
        st, r = upload(srv, "evil.off", cube_off, headers=hdr)
        assert st == 403, (hdr, r)
        st, r = jrequest(srv, "POST", "/api/model/m1/features", b'{"patch": 5}', headers=hdr)
        assert st == 403, (hdr, r)
        st, r = jrequest(srv, "POST", "/api/compare", b'{"a": "m1", "b": "m1"}', headers=hdr)
        assert st == 403, (hdr, r)
    assert n_models(srv) == before_models and len(srv.session.jobs) == before_jobs
    # the page's own origin is accepted (with the token)
    for own in (f"http://127.0.0.1:{port}", f"http://localhost:{port}"):
        hdr = {"Origin": own, "Sec-Fetch-Site": "same-origin"}
        assert upload(srv, "own.off", cube_off, headers=hdr)[0] == 200


def test_simple_text_plain_requests_without_token_refused(srv, cube_off):
    before = n_models(srv)
    simple = {"Content-Type": "text/plain"}  # what a cross-origin <form>/fetch can send freely
    st, r = upload(srv, "evil.off", cube_off, headers=simple, token=False)
    assert st == 403 and TOKEN_HEADER in r["error"]
    st, _ = upload(
        srv, "evil.off", cube_off, headers={**simple, TOKEN_HEADER: "guess"}, token=False
    )
    assert st == 403
    assert n_models(srv) == before
    assert upload(srv, "c.off", cube_off)[0] == 200
    mid = f"m{before + 1}"
    st, _ = jrequest(srv, "POST", f"/api/model/{mid}/denoise", b"{}", simple, token=False)
    assert st == 403 and len(srv.session.jobs) == 0
    # reads need the token too (no cross-origin <img>/<script> triggering computations)
    for path in ("/api/state", f"/api/model/{mid}/lod?max_faces=10", f"/api/model/{mid}/download"):
        assert request(srv, "GET", path, token=False)[0] == 403
    assert not srv.session.models[mid].arrays
    assert request(srv, "GET", "/api/state")[0] == 200


def test_preflight_is_never_approved(srv):
    hdr = {
        "Origin": EVIL,
        "Access-Control-Request-Method": "POST",
        "Access-Control-Request-Headers": TOKEN_HEADER.lower(),
    }
    st, h, _ = request(srv, "OPTIONS", "/api/upload?name=x.off", headers=hdr, token=False)
    assert st == 403
    assert not [k for k in h if k.lower().startswith("access-control-")]
    for path in ("/", "/api/state", "/static/app.js"):
        _, h, _ = request(srv, "GET", path, headers={"Origin": EVIL})
        assert "Access-Control-Allow-Origin" not in h
    assert request(srv, "PUT", "/api/state")[0] == 405


def test_token_is_delivered_in_the_page_only(srv):
    st, h, html = request(srv, "GET", "/", token=False)
    assert st == 200 and srv.token.encode() in html and b"__SPECTRAGEO_TOKEN__" not in html
    assert len(srv.token) >= 40  # 32 random bytes
    csp = h["Content-Security-Policy"]
    assert "script-src 'self' 'sha256-" in csp and "frame-ancestors 'none'" in csp
    assert "unsafe-inline" not in csp and "unsafe-eval" not in csp
    assert h["X-Content-Type-Options"] == "nosniff" and h["X-Frame-Options"] == "DENY"
    # another server, another token
    other = ViewerServer([], port=0)
    try:
        assert other.token != srv.token
    finally:
        other.stop()
    # a DNS-rebinding page (foreign Host) gets neither the page nor the API
    assert request(srv, "GET", "/", headers={"Host": f"evil.example:{srv.port}"})[0] == 403


# --------------------------------------------------------------------------- names and headers
def test_download_name_cannot_inject_headers(srv, cube_off):
    name = "a\r\nSet-Cookie: x=1\r\n\r\n<b>.off"
    st, r = upload(srv, name, cube_off)
    assert st == 200
    assert "\r" not in r["model"]["name"] and "\n" not in r["model"]["name"]
    mid = r["model"]["id"]
    # also a name that reached the session without passing through the upload route
    m2 = srv.session.add(Mesh(*cube(2)), 'b"\r\nSet-Cookie: y=2;.ply')
    for m in (mid, m2.id):
        head = (
            f"GET /api/model/{m}/download?format=.off HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            f"{TOKEN_HEADER}: {srv.token}\r\nConnection: close\r\n\r\n"
        ).encode()
        resp = raw_exchange(srv, head)
        header_block = resp.split(b"\r\n\r\n", 1)[0].decode("latin-1")
        lines = header_block.split("\r\n")
        assert lines[0] == "HTTP/1.1 200 OK"
        assert not [x for x in lines if x.lower().startswith("set-cookie")], lines
        cd = [x for x in lines if x.startswith("Content-Disposition:")]
        assert len(cd) == 1 and "filename*=UTF-8''" in cd[0]
        fallback = cd[0].split('filename="', 1)[1].split('"', 1)[0]
        assert fallback.endswith(".off") and all(c not in fallback for c in '"\\;\r\n ')


def test_content_disposition_rfc6266():
    v = content_disposition("Модель «тест».off")
    assert v.startswith('attachment; filename="')
    assert "filename*=UTF-8''%D0%9C%D0%BE%D0%B4%D0%B5%D0%BB%D1%8C" in v
    assert v.isascii() and "\r" not in v and "\n" not in v
    assert content_disposition('q"uo;te\r\n.ply').split("; ")[1] == 'filename="q_uo_te.ply"'
    assert 'filename="download"' in content_disposition("\r\n")


def test_unicode_long_and_bad_names(srv, cube_off):
    nfd = unicodedata.normalize("NFD", "Modèle-ünï 模型.off")
    st, r = upload(srv, nfd, cube_off)
    assert st == 200, r
    assert r["model"]["name"] == unicodedata.normalize("NFC", nfd)
    st, r = upload(srv, "x" * 5000 + ".off", cube_off)
    assert st == 200, r
    assert len(r["model"]["name"]) <= 200 and r["model"]["name"].endswith("\u2026.off")
    st, r = upload(srv, "a\x00b\x1b[31mc\u202egnp.off", cube_off)
    assert st == 200 and r["model"]["name"] == "ab[31mcgnp.off"
    st, r = upload(srv, "../../x/y.OFF", cube_off)
    assert st == 200 and r["model"]["name"] == "y.OFF"
    st, r = jrequest(srv, "POST", "/api/upload?name=%ED%A0%80.off", cube_off)  # not UTF-8
    assert st == 200
    for bad in ("", "..", "/", "\r\n", "x" * 5000, "noext", "a.\u00e9xt"):
        st, r = upload(srv, bad, cube_off)
        assert st == 400 and "could not read" in r["error"], (bad, st, r)
    # long and hostile names of scalar-field uploads too
    mid = f"m{max(int(k[1:]) for k in srv.session.models)}"
    vals = " ".join(["1"] * 98).encode()  # one per vertex of cube(3)
    st, r = jrequest(srv, "POST", f"/api/field-upload?model={mid}&name=" + quote("é" * 3000), vals)
    assert st == 200 and len(r["field"]) <= 206


def test_clean_name_unit():
    assert clean_name("a\u2028b.ply") == "a b.ply"
    assert clean_name("\u202e") == "upload"
    long = clean_name("é" * 300 + ".ply.gz")
    assert len(long) == 200 and long.endswith("\u2026.ply.gz")
    assert clean_name("C:\\Users\\me\\mesh.obj") == "mesh.obj"


# --------------------------------------------------------------------------- bodies and uploads
def test_oversized_body_refused_quickly_and_server_keeps_serving(srv):
    junk = b"\0" * (4 << 20)
    rss0 = rss_mb()
    t0 = time.perf_counter()
    head = (
        "POST /api/upload?name=bomb.ply HTTP/1.1\r\nHost: 127.0.0.1\r\n"
        f"{TOKEN_HEADER}: {srv.token}\r\nContent-Length: 5000000000\r\n\r\n"
    ).encode()
    resp = raw_exchange(srv, head, junk)
    dt = time.perf_counter() - t0
    rss1 = rss_mb()
    assert resp.startswith(b"HTTP/1.1 413"), resp[:200]
    assert b"limit" in resp and b"--max-upload" in resp
    assert dt < 5.0  # refused from the Content-Length (about 1 s of lingering at most)
    assert rss1 - rss0 < 32, (rss0, rss1)  # nothing of the body buffered
    assert not list(srv.tmp_dir.iterdir())  # nothing written
    assert request(srv, "GET", "/api/state")[0] == 200
    # `Expect: 100-continue`: refused before the body is sent
    head = head.replace(b"\r\n\r\n", b"\r\nExpect: 100-continue\r\n\r\n")
    t0 = time.perf_counter()
    resp = raw_exchange(srv, head)
    assert resp.startswith(b"HTTP/1.1 413") and time.perf_counter() - t0 < 2.0
    # no Content-Length, chunked, or a malformed one
    resp = raw_exchange(
        srv,
        b"POST /api/upload?name=a.off HTTP/1.1\r\nHost: 127.0.0.1\r\n"
        + f"{TOKEN_HEADER}: {srv.token}\r\n\r\n".encode(),
    )
    assert resp.startswith(b"HTTP/1.1 411")
    assert request(srv, "POST", "/api/upload?name=a.off", b"")[0] == 400  # empty: not a model
    resp = raw_exchange(
        srv,
        b"POST /api/upload?name=a.off HTTP/1.1\r\nHost: 127.0.0.1\r\n"
        + f"{TOKEN_HEADER}: {srv.token}\r\n".encode()
        + b"Transfer-Encoding: chunked\r\n\r\n5\r\nhello\r\n0\r\n\r\n",
    )
    assert resp.startswith(b"HTTP/1.1 411")
    resp = raw_exchange(
        srv,
        b"POST /api/upload?name=a.off HTTP/1.1\r\nHost: 127.0.0.1\r\n"
        + f"{TOKEN_HEADER}: {srv.token}\r\n".encode()
        + b"Content-Length: -5\r\n\r\n",
    )
    assert resp.startswith(b"HTTP/1.1 400")
    # JSON bodies are small
    st, r = jrequest(srv, "POST", "/api/compare", b" " * (2 << 20))
    assert st == 413
    assert request(srv, "GET", "/api/state")[0] == 200


def test_upload_limit_option_and_environment(cube_off, monkeypatch):
    monkeypatch.setenv("SPECTRAGEO_VIEW_MAX_UPLOAD_MB", "0.001")  # about 1 kB
    with ViewerServer([], port=0).start() as s:
        assert s.limits.max_upload_bytes == 1048
        st, r = upload(s, "c.off", cube_off)
        assert st == 413 and "1048 bytes" in r["error"]
        st, r = upload(s, "tiny.xyz", b"0 0 0\n1 0 0\n0 1 0\n")
        assert st == 200, r
        assert jrequest(s, "GET", "/api/state")[1]["limits"]["max_upload_bytes"] == 1048
    with ViewerServer([], port=0, max_upload_mb=10).start() as s:  # arguments win
        assert s.limits.max_upload_mb == 10
        assert upload(s, "c.off", cube_off)[0] == 200
    monkeypatch.setenv("SPECTRAGEO_VIEW_MAX_UPLOAD_MB", "lots")
    with pytest.raises(InvalidInputError, match="SPECTRAGEO_VIEW_MAX_UPLOAD_MB` must be a number"):
        ViewerLimits.from_env()


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"max_upload_mb": 0}, "`max_upload_mb` must be a number > 0"),
        ({"max_memory_mb": float("inf")}, "`max_memory_mb` must be a number > 0"),
        ({"max_models": 0}, r"`max_models` must be an integer >= 1"),
        ({"max_jobs": 1.5}, r"`max_jobs` must be an integer >= 1"),
        ({"max_uploads": True}, r"`max_uploads` must be an integer >= 1"),
        ({"request_timeout": -1}, "`request_timeout` must be a number > 0"),
    ],
)
def test_limits_validation(kw, match):
    with pytest.raises(InvalidInputError, match=match):
        ViewerLimits(**kw)


def test_limits_unknown_option():
    with pytest.raises(InvalidInputError, match="unknown viewer limit"):
        ViewerLimits.from_env(max_everything=3)


def test_upload_is_streamed_to_disk(srv):
    total = 48 << 20
    head = (
        "POST /api/upload?name=big.ply HTTP/1.1\r\nHost: 127.0.0.1\r\n"
        f"{TOKEN_HEADER}: {srv.token}\r\nContent-Length: {total}\r\n\r\n"
    ).encode()
    block = b"\0" * (1 << 20)
    rss0 = rss_mb()
    peak = rss0
    with socket.create_connection(("127.0.0.1", srv.port), timeout=30) as c:
        c.sendall(head + b"ply\nformat nonsense 1.0\nend_header\n")
        sent = 0
        while sent < total - (1 << 20):
            c.sendall(block)
            sent += len(block)
            peak = max(peak, rss_mb())
        t0 = time.time()
        while True:  # the body is on disk as it arrives
            files = list(srv.tmp_dir.glob("upload-*.ply"))
            if files and files[0].stat().st_size >= sent - (2 << 20) or time.time() - t0 > 10:
                break
            time.sleep(0.05)
        assert files and files[0].stat().st_size >= sent - (2 << 20)
        peak = max(peak, rss_mb())
        c.sendall(b"\0" * (total - sent - len(b"ply\nformat nonsense 1.0\nend_header\n")))
        resp = c.recv(65536)
    assert resp.startswith(b"HTTP/1.1 400"), resp[:300]
    assert peak - rss0 < 24, (rss0, peak)  # a 48 MB body, not held in memory
    assert not list(srv.tmp_dir.iterdir())  # removed after reading


def test_compression_bomb_refused(tmp_path):
    raw = b"\0" * (6 << 20)
    with ViewerServer([], port=0, max_memory_mb=2).start() as s:
        st, r = upload(s, "bomb.ply.gz", gzip.compress(raw, 9))
        assert st == 400 and "decompresses to more than 2 MB" in r["error"]
        np.savez_compressed(tmp_path / "bomb.npz", vertices=np.zeros((1, 500_000, 3)))
        st, r = upload(s, "bomb.npz", (tmp_path / "bomb.npz").read_bytes())
        assert st == 400 and "decompresses to more than" in r["error"]
        st, r = upload(s, "bad.ply.gz", b"\x1f\x8b\x08\x00garbage")
        assert st == 400 and "could not read bad.ply.gz" in r["error"]
        assert request(s, "GET", "/api/state")[0] == 200


def test_concurrent_uploads_bounded(cube_off):
    with ViewerServer([], port=0, max_uploads=1).start() as s:
        c = socket.create_connection(("127.0.0.1", s.port), timeout=10)
        try:
            c.sendall(
                (
                    "POST /api/upload?name=slow.off HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                    f"{TOKEN_HEADER}: {s.token}\r\nContent-Length: {len(cube_off)}\r\n\r\n"
                ).encode()
                + cube_off[:10]
            )
            t0 = time.time()
            while not list(s.tmp_dir.glob("upload-*")) and time.time() - t0 < 5:
                time.sleep(0.02)
            st, r = upload(s, "second.off", cube_off)
            assert st == 429 and "too many uploads" in r["error"]
            c.sendall(cube_off[10:])
            assert c.recv(65536).startswith(b"HTTP/1.1 200")
        finally:
            c.close()
        assert upload(s, "third.off", cube_off)[0] == 200


# --------------------------------------------------------------------------- jobs and models
def test_job_queue_is_bounded(cube_off):
    with ViewerServer([], port=0, max_jobs=1, max_queued=1).start() as s:
        assert upload(s, "c.off", cube_off)[0] == 200
        gate = threading.Event()

        def slow(m, patch, frame, job=None):
            gate.wait(20)
            return {"ok": True}

        s.session.features = slow
        body = b'{"patch": 5}'
        st1, j1 = jrequest(s, "POST", "/api/model/m1/features", body)
        st2, j2 = jrequest(s, "POST", "/api/model/m1/features", body)
        st3, r3 = jrequest(s, "POST", "/api/model/m1/features", body)
        assert (st1, st2) == (200, 200)
        assert st3 == 429 and "busy" in r3["error"]
        st, h, _ = request(s, "POST", "/api/compare", b'{"a": "m1", "b": "m1"}')
        assert st == 429 and h["Retry-After"] == "1"
        assert jrequest(s, "GET", f"/api/job/{j2['job']}")[1]["queued"] is True
        assert len(s.session.jobs) == 2
        gate.set()
        for jid in (j1["job"], j2["job"]):
            t0 = time.time()
            while jrequest(s, "GET", f"/api/job/{jid}")[1]["state"] == "running":
                assert time.time() - t0 < 20
                time.sleep(0.02)
        assert jrequest(s, "POST", "/api/model/m1/features", body)[0] == 200


def test_least_recently_used_models_are_evicted():
    V, F = cube(3)
    s = ViewerSession(ViewerLimits(max_models=2))
    a, b = s.add(Mesh(V, F), "a.off"), s.add(Mesh(V, F), "b.off")
    s.get(a.id)  # a is now more recent than b
    c = s.add(Mesh(V, F), "c.off")
    assert list(s.models) == [a.id, c.id]
    with pytest.raises(InvalidInputError, match=r"model 'm2' \(b.off\) was unloaded"):
        s.get(b.id)
    # byte budget: room for two cubes and their arrays, not three
    size = s.models[a.id].nbytes
    s = ViewerSession(ViewerLimits(max_memory_mb=2.5 * size / 2**20))
    ms = [s.add(Mesh(V, F), f"{k}.off") for k in range(3)]
    assert list(s.models) == [ms[1].id, ms[2].id]
    assert s.nbytes <= 2.5 * size
    s.get(ms[1].id).arrays["big"] = np.zeros(size // 8 * 2)  # computed arrays count too
    assert s.trim() == [ms[2].id]
    # the newest model and the ones a job uses stay, even beyond the budget
    s = ViewerSession(ViewerLimits(max_models=1))
    x = s.add(Mesh(V, F), "x.off")
    x.pins = 1
    y = s.add(Mesh(V, F), "y.off")
    assert set(s.models) == {x.id, y.id}
    x.pins = 0
    assert s.trim() == [x.id]


def test_eviction_over_http(cube_off):
    with ViewerServer([], port=0, max_models=2).start() as s:
        for k in range(5):
            assert upload(s, f"u{k}.off", cube_off)[0] == 200
        st = jrequest(s, "GET", "/api/state")[1]
        assert [m["name"] for m in st["models"]] == ["u3.off", "u4.off"]
        st, r = jrequest(s, "GET", "/api/model/m1")
        assert st == 400 and "was unloaded" in r["error"] and "--max-models" in r["error"]


# --------------------------------------------------------------------------- connections
def _closed_within(c: socket.socket, seconds: float) -> float | None:
    """Seconds until the server closes ``c`` (None if still open after ``seconds``)."""
    t0 = time.perf_counter()
    c.settimeout(seconds)
    try:
        while c.recv(4096):
            pass
    except TimeoutError:
        return None
    except OSError:
        pass
    return time.perf_counter() - t0


def test_idle_slow_and_stalled_connections_time_out(cube_off):
    with ViewerServer([], port=0, request_timeout=0.6, max_uploads=1).start() as s:
        with socket.create_connection(("127.0.0.1", s.port)) as idle:
            dt = _closed_within(idle, 5)
            assert dt is not None and dt < 2.0
        # slowloris: one header byte every 0.1 s never completes a request
        with socket.create_connection(("127.0.0.1", s.port)) as slow:
            slow.settimeout(0.1)
            t0 = time.perf_counter()
            data = b"GET /api/state HTTP/1.1\r\nHost: 127.0.0.1\r\nX-A: " + b"a" * 200
            closed = None
            for b in data:
                try:
                    slow.sendall(bytes([b]))
                    if slow.recv(4096) == b"":
                        closed = time.perf_counter() - t0
                        break
                except TimeoutError:
                    continue
                except OSError:
                    closed = time.perf_counter() - t0
                    break
            assert closed is not None and closed < 2.5, closed
        # a stalled upload body: dropped after the timeout, its slot and file released
        with socket.create_connection(("127.0.0.1", s.port)) as stall:
            stall.sendall(
                (
                    "POST /api/upload?name=s.off HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                    f"{TOKEN_HEADER}: {s.token}\r\nContent-Length: 100000\r\n\r\nOFF\n"
                ).encode()
            )
            assert _closed_within(stall, 5) is not None
        time.sleep(0.1)
        assert not list(s.tmp_dir.iterdir())
        assert upload(s, "after.off", cube_off)[0] == 200
        # keep-alive still works within the timeout
        c = http.client.HTTPConnection("127.0.0.1", s.port, timeout=5)
        for _ in range(3):
            c.request("GET", "/api/state", headers=s.api_headers)
            assert c.getresponse().read() and True
        c.close()


def test_connection_cap():
    with ViewerServer([], port=0, max_connections=3, request_timeout=10).start() as s:
        held = [socket.create_connection(("127.0.0.1", s.port)) for _ in range(3)]
        t0 = time.time()
        while s.httpd.active_connections < 3 and time.time() - t0 < 5:
            time.sleep(0.02)
        with socket.create_connection(("127.0.0.1", s.port), timeout=5) as extra:
            assert extra.recv(4096).startswith(b"HTTP/1.1 503")
        for c in held:
            c.close()
        t0 = time.time()
        while s.httpd.active_connections and time.time() - t0 < 5:
            time.sleep(0.02)
        assert request(s, "GET", "/api/state")[0] == 200


# --------------------------------------------------------------------------- temporary folders
def test_temp_folder_removed_on_stop(cube_off):
    s = ViewerServer([], port=0).start()
    d = s.tmp_dir
    assert d.is_dir() and d.name.startswith(f"spectrageo-view-{os.getpid()}-")
    assert upload(s, "c.off", cube_off)[0] == 200
    assert request(s, "GET", "/api/model/m1/download?format=.ply")[0] == 200
    assert not list(d.iterdir())  # uploads and downloads leave nothing behind
    s.stop()
    assert not d.exists()
    s.stop()  # idempotent
    # a server that fails to start removes its folder too
    before = set(Path(s.tmp_dir).parent.glob(f"spectrageo-view-{os.getpid()}-*"))
    with pytest.raises(InvalidInputError):
        ViewerServer(["missing-file.ply"], port=0)
    assert set(Path(s.tmp_dir).parent.glob(f"spectrageo-view-{os.getpid()}-*")) == before


def test_stale_temp_folders_of_dead_processes_removed(tmp_path, monkeypatch):
    import tempfile

    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    dead = tmp_path / f"spectrageo-view-{p.pid}-abc123"
    alive = tmp_path / f"spectrageo-view-{os.getppid()}-def456"
    mine = tmp_path / f"spectrageo-view-{os.getpid()}-ghi789"
    legacy_old = tmp_path / "spectrageo-view-k2j3_x9a"
    legacy_new = tmp_path / "spectrageo-view-q1w2e3r4"
    for d in (dead, alive, mine, legacy_old, legacy_new):
        d.mkdir()
        (d / "upload.ply").write_bytes(b"x")
    os.utime(legacy_old, (time.time() - 7200, time.time() - 7200))
    (tmp_path / "spectrageo-view-file").write_text("not a folder")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    s = ViewerServer([], port=0)
    try:
        assert sorted(s.removed_stale) == sorted([dead, legacy_old])
        assert not dead.exists() and not legacy_old.exists()
        assert alive.exists() and mine.exists() and legacy_new.exists()
        assert s.tmp_dir.parent == tmp_path
    finally:
        s.stop()
    assert remove_stale_temp_dirs(tmp_path) == []


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_cli_signal_removes_temp_folder(tmp_path, sig):
    env = dict(os.environ, TMPDIR=str(tmp_path), PYTHONUNBUFFERED="1")
    code = (
        "import sys; from spectrageo.cli.main import main; "
        "sys.exit(main(['view', '--port', '0', '--no-browser', '--max-upload', '5']))"
    )
    # a runner started as a background job ignores SIGINT and its children inherit that: give
    # the viewer the default disposition so that Python installs its Ctrl+C handler
    p = subprocess.Popen(
        [sys.executable, "-c", code],
        env=env,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        for _ in range(50):
            line = p.stderr.readline()
            if "spectrageo viewer on" in line or not line:
                break
        assert "spectrageo viewer on http://127.0.0.1:" in line and "up to 5 MB" in line, line
        dirs = list(tmp_path.glob(f"spectrageo-view-{p.pid}-*"))
        assert len(dirs) == 1 and dirs[0].is_dir()
        p.send_signal(sig)
        assert p.wait(timeout=30) == 0
        assert not dirs[0].exists()
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


def test_cli_limit_options(monkeypatch):
    from spectrageo.cli import main as cli_main
    from spectrageo.viewer import server as srvmod

    seen = {}

    def fake_serve(self):
        seen["limits"] = self.limits
        raise KeyboardInterrupt

    monkeypatch.setattr(srvmod.ViewerServer, "serve_forever", fake_serve)
    argv = ["view", "--port", "0", "--no-browser", "--max-upload", "12.5"]
    assert cli_main.main(argv + ["--max-models", "3", "--max-memory", "100"]) == 0
    lim = seen["limits"]
    assert (lim.max_upload_mb, lim.max_models, lim.max_memory_mb) == (12.5, 3, 100.0)
    assert cli_main.main(["view", "--port", "0", "--no-browser", "--max-upload", "0"]) == 2
    assert cli_main.main(["view", "--port", "0", "--no-browser", "--max-models", "-1"]) == 2


# --------------------------------------------------------------------------- in Chromium
CHROMIUM = os.environ.get("SPECTRAGEO_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
CHROME_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
HOSTILE = '<img src=x onerror="window.__pwned=1">.off'


@pytest.fixture(scope="module")
def browser():
    sync_api = require_module("playwright.sync_api")
    if not Path(CHROMIUM).exists():  # a skip on a user's machine, a failure under CI=true
        skip_or_fail(f"chromium not found at {CHROMIUM} (apt-get install chromium)")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROME_ARGS)
        yield b
        b.close()


def _open(browser, srv, *, bypass_csp: bool):
    ctx = browser.new_context(viewport={"width": 1000, "height": 700}, bypass_csp=bypass_csp)
    page = ctx.new_page()
    page.set_default_timeout(60_000)
    page.console_lines = []
    page.on("console", lambda m: page.console_lines.append(m.text))
    page.goto(srv.url)
    page.wait_for_selector("body[data-ready='1']")
    return ctx, page


def test_hostile_model_name_is_shown_as_text(browser, srv, cube_off):
    # CSP bypassed: this checks the escaping itself, not the CSP that would also block the handler
    ctx, page = _open(browser, srv, bypass_csp=True)
    try:
        for name in ("ref.off", HOSTILE):
            page.set_input_files(
                "#file-input", files=[{"name": name, "mimeType": "text/plain", "buffer": cube_off}]
            )
            page.wait_for_function(
                "n => document.getElementById('info-name').textContent === n", arg=name
            )
            page.wait_for_function("document.body.dataset.busy === '0'")
        page.select_option("#model-select", label="ref.off (mesh)")
        page.wait_for_function("document.body.dataset.busy === '0'")
        page.select_option("#compare-select", label=f"{HOSTILE} (mesh)")
        page.click("#compare-btn")
        page.wait_for_selector("#metrics-table tr[data-metric]")
        page.wait_for_timeout(300)  # an injected onerror would have fired by now
        assert page.evaluate("window.__pwned") is None
        assert page.locator("#metrics-table img, #model-select img, #sidebar img").count() == 0
        header = page.inner_text("#metrics-table th[colspan]")
        assert header == f"{HOSTILE} vs ref.off"
        options = page.eval_on_selector_all("#compare-select option", "o => o.map(x => x.text)")
        assert f"{HOSTILE} (mesh)" in options
        assert HOSTILE in page.inner_text("#caption-right")
    finally:
        ctx.close()


def test_page_works_under_its_content_security_policy(browser, srv, cube_off):
    ctx, page = _open(browser, srv, bypass_csp=False)
    try:
        page.set_input_files(
            "#file-input", files=[{"name": "c.off", "mimeType": "text/plain", "buffer": cube_off}]
        )
        page.wait_for_selector("#message:text-is('loaded c.off')")
        assert page.inner_text("#info-name") == "c.off"
        assert page.locator("#info-features").inner_text().isdigit()
        assert not [x for x in page.console_lines if "Content Security Policy" in x]
        # an injected inline handler would not run even if escaping failed
        page.evaluate(
            "() => { const d = document.createElement('div');"
            " d.innerHTML = '<img src=x onerror=\"window.__pwned=1\">';"
            " document.body.appendChild(d); }"
        )
        page.wait_for_timeout(300)
        assert page.evaluate("window.__pwned") is None
        # a wrong token is refused
        status = page.evaluate(
            "async () => (await fetch('/api/state', {headers: {'X-Spectrageo-Token': 'x'}})).status"
        )
        assert status == 403
    finally:
        ctx.close()


CSRF = """async (u) => {
  const off = 'OFF\\n3 1 0\\n0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n';
  const out = [];
  for (const opts of [
    { method: 'POST', mode: 'no-cors', headers: { 'Content-Type': 'text/plain' }, body: off },
    { method: 'POST', headers: { 'X-Spectrageo-Token': 'guess' }, body: off },
  ]) {
    try { const r = await fetch(u, opts); out.push(r.type + ':' + r.status); }
    catch (e) { out.push('blocked'); }
  }
  return out;
}"""


@pytest.fixture
def evil_site():
    """A page on another origin of this machine (``http://localhost:PORT``): no Private Network
    Access rule stands between it and the viewer, only the viewer's own checks."""
    from http.server import BaseHTTPRequestHandler, HTTPServer

    class Evil(BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802
            body = b"<p>evil</p>"
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *a):
            pass

    httpd = HTTPServer(("127.0.0.1", 0), Evil)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    yield f"http://localhost:{httpd.server_port}/"
    httpd.shutdown()
    httpd.server_close()


def test_page_on_another_origin_cannot_upload(browser, srv, evil_site):
    ctx = browser.new_context()
    try:
        page = ctx.new_page()
        page.goto(evil_site)
        out = page.evaluate(CSRF, srv.url + "api/upload?name=evil.off")
        assert out[1] == "blocked", out  # the preflight of the token header is refused
        assert n_models(srv) == 0  # the text/plain no-cors POST reached the server: refused
    finally:
        ctx.close()
