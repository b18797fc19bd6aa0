"""The viewer's HTTP request handler and threaded server (routes: :mod:`.server`)."""

from __future__ import annotations

import base64
import functools
import hashlib
import hmac
import ipaddress
import json
import mimetypes
import os
import re
import socket
import threading
import time
import traceback
import uuid
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import parse_qs, unquote

import numpy as np

from .._errors import InvalidInputError, SpectrageoError
from . import _analysis
from ._files import clean_name, content_disposition, file_suffix
from ._jobs import ViewerBusyError, _error_text
from ._limits import CHUNK, MAX_JSON_BODY, MIN_BODY_RATE, ViewerLimits
from ._session import Model, ViewerSession, _ext

STATIC_DIR = Path(__file__).resolve().parent / "static"
TOKEN_HEADER = "X-Spectrageo-Token"
TOKEN_PLACEHOLDER = b"__SPECTRAGEO_TOKEN__"
LINGER_S = 1.0  # at most this long and ...
LINGER_BYTES = 16 << 20  # ... this much of an unread body is drained after a refusal, so that
# the client can read the answer before the connection is reset
IDLE_GRACE_S = 1.0  # a connection waiting this long for its request can give way to a new one
LOOPBACK_NAMES = ("127.0.0.1", "localhost")
# Host = host [":" port]: a name or IPv4 address, or a bracketed IPv6 address (RFC 9110 7.2)
_HOST = re.compile(
    r"(?:(?P<name>[A-Za-z0-9.-]+)|\[(?P<v6>[0-9A-Fa-f:.]+)\])(?::(?P<port>[0-9]{1,5}))?"
)


def _header_value(v) -> str:
    """A header value without CR/LF (defence in depth: no header is ever built from raw input)."""
    return re.sub(r"[\r\n\x00]+", " ", str(v))


class _Refused(Exception):
    """An HTTP refusal decided before or instead of the work (403, 411, 413, 429 ...)."""

    def __init__(self, status: int, message: str, headers: dict | None = None):
        super().__init__(message)
        self.status = status
        self.headers = headers or {}


_IMPORTMAP = re.compile(rb'<script type="importmap">(.*?)</script>', re.S)


@functools.lru_cache(maxsize=4)
def _index_csp(index_html: bytes) -> str:
    """Content-Security-Policy of the page: own scripts plus the inline import map (by hash)."""
    hashes = " ".join(
        "'sha256-" + base64.b64encode(hashlib.sha256(m.group(1)).digest()).decode() + "'"
        for m in _IMPORTMAP.finditer(index_html)
    )
    return (
        f"default-src 'self'; script-src 'self' {hashes}; style-src 'self'; img-src 'self' data: "
        "blob:; connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'none'; "
        "frame-ancestors 'none'"
    )


class _Handler(BaseHTTPRequestHandler):
    server_version = "spectrageo-view"
    protocol_version = "HTTP/1.1"
    # set on the subclass made by ViewerServer
    session: ViewerSession
    token: str = ""
    limits: ViewerLimits = ViewerLimits()
    tmp_dir: Path
    upload_slots: threading.BoundedSemaphore
    quiet = True
    timeout = 30.0  # socket timeout of every read (StreamRequestHandler applies it)

    def log_message(self, fmt, *args):  # noqa: D401 - silence the default stderr log
        if not self.quiet:
            super().log_message(fmt, *args)

    # ---- connection handling
    def handle(self):
        try:
            super().handle()
        except OSError:  # timed out, reset, or closed by the deadline watcher: just drop it
            pass

    def handle_one_request(self):
        # the whole request line + headers must arrive within `request_timeout`; an idle
        # keep-alive connection is closed after it (see _HTTPServer._reap)
        self._unread = 0
        self.server.watch(self.connection, self.timeout)
        try:
            super().handle_one_request()
        finally:
            self.server.unwatch(self.connection)

    def parse_request(self):
        ok = super().parse_request()
        self.server.unwatch(self.connection)
        return ok

    def handle_expect_100(self):
        # `Expect: 100-continue`: refuse before the client sends the body
        try:
            self._precheck(self._parts())
            length = self._declared_length()
            limit = self._limit_for(self._parts())
            if length is not None and length > limit:
                raise self._too_large(length, limit)
        except _Refused as exc:
            self.close_connection = True
            self._json({"error": str(exc)}, exc.status, exc.headers)
            return False
        return super().handle_expect_100()

    def _linger(self) -> None:
        """After refusing a body: drain it briefly so the client reads the answer, then close."""
        self.close_connection = True
        try:
            self.wfile.flush()
            self.connection.shutdown(socket.SHUT_WR)
            self.connection.settimeout(0.25)
            end = time.monotonic() + LINGER_S
            left = min(self._unread, LINGER_BYTES)
            while left > 0 and time.monotonic() < end:
                c = self.connection.recv(min(left, 1 << 16))
                if not c:
                    break
                left -= len(c)
        except OSError:
            pass
        self._unread = 0

    # ---- replies
    def _send(self, status: int, body: bytes, ctype: str, headers: dict | None = None) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("X-Frame-Options", "DENY")
        self.send_header("Referrer-Policy", "no-referrer")
        self.send_header("Cross-Origin-Resource-Policy", "same-origin")
        for k, v in (headers or {}).items():
            self.send_header(k, _header_value(v))
        if getattr(self, "_unread", 0) or getattr(self, "_bad_framing", False):
            self.send_header("Connection", "close")  # the body was not read: no keep-alive
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, obj, status: int = 200, headers: dict | None = None) -> None:
        self._send(status, json.dumps(obj).encode(), "application/json", headers)

    def _array(self, a: np.ndarray) -> None:
        a = np.ascontiguousarray(a)
        dt = a.dtype.newbyteorder("<") if a.dtype.byteorder == ">" else a.dtype
        self._send(
            200,
            a.astype(dt, copy=False).tobytes(),
            "application/octet-stream",
            {"X-Dtype": dt.name, "X-Shape": ",".join(map(str, a.shape))},
        )

    # ---- request bodies
    def _declared_length(self) -> int | None:
        """Content-Length (None when absent); malformed framing is refused."""
        if self.headers.get("Transfer-Encoding"):
            self._bad_framing = True
            raise _Refused(411, "chunked request bodies are not supported; send a Content-Length.")
        raw = self.headers.get_all("Content-Length") or []
        if not raw:
            return None
        if len(set(raw)) != 1 or not raw[0].strip().isdigit():
            self._bad_framing = True
            raise _Refused(400, f"invalid Content-Length header: {', '.join(raw)[:40]!r}.")
        return int(raw[0])

    def _too_large(self, n: int, limit: int) -> _Refused:
        what = "upload" if limit == self.limits.max_upload_bytes else "request body"
        hint = " (spectrageo view --max-upload MB)" if what == "upload" else ""
        return _Refused(
            413,
            f"{what} too large: {n} bytes; the limit is {limit} bytes "
            f"({limit / 2**20:g} MB){hint}.",
        )

    def _limit_for(self, parts: list[str]) -> int:
        if parts[:2] in (["api", "upload"], ["api", "field-upload"]):
            return self.limits.max_upload_bytes
        return MAX_JSON_BODY

    def _require_length(self, limit: int) -> int:
        n = self._declared_length()
        if n is None:
            raise _Refused(411, "the request needs a Content-Length header.")
        if n > limit:
            raise self._too_large(n, limit)
        return n

    def _read_into(self, out, n: int) -> None:
        """Read ``n`` body bytes into ``out``: each pause at most ``request_timeout``, the whole
        body within ``request_timeout + n / MIN_BODY_RATE`` seconds (else 408)."""
        left = n
        start = time.monotonic()
        deadline = start + self.timeout + n / MIN_BODY_RATE
        try:
            while left > 0:
                rest = deadline - time.monotonic()
                if rest <= 0:
                    raise TimeoutError
                self.connection.settimeout(min(self.timeout, rest))
                c = self.rfile.read1(min(left, CHUNK))
                if not c:
                    raise ConnectionError("the client closed the connection during the upload")
                out.write(c)
                left -= len(c)
                self._unread = left
        except TimeoutError:
            raise _Refused(
                408,
                f"request body not received in time: {n - left} of {n} bytes in "
                f"{time.monotonic() - start:.0f} s (request_timeout {self.timeout:g} s, then "
                f"{MIN_BODY_RATE >> 10} KiB/s at least).",
            ) from None
        finally:
            self.connection.settimeout(self.timeout)

    def _receive(self, suffix: str) -> Path:
        """Stream the body (at most ``max_upload_mb``) to a private temporary file."""
        n = self._require_length(self.limits.max_upload_bytes)
        p = self.tmp_dir / f"upload-{uuid.uuid4().hex}{suffix}"
        try:
            with open(p, "xb") as f:
                self._read_into(f, n)
        except BaseException:
            p.unlink(missing_ok=True)
            raise
        return p

    def _params(self) -> dict:
        n = self._require_length(MAX_JSON_BODY) if self._declared_length() else 0
        if not n:
            return {}
        import io as _io

        buf = _io.BytesIO()
        self._read_into(buf, n)
        try:
            obj = json.loads(buf.getvalue())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InvalidInputError(f"request body is not JSON: {exc}") from None
        if not isinstance(obj, dict):
            raise InvalidInputError("request body must be a JSON object.")
        return obj

    # ---- dispatch
    def do_GET(self):  # noqa: N802 - HEAD too (_send leaves out the body)
        self._dispatch("GET")

    def _dispatch_command(self):  # OPTIONS (CORS preflights are never approved), PUT, ... refused
        self._dispatch(self.command)

    do_HEAD = do_GET
    do_POST = do_OPTIONS = do_PUT = do_DELETE = do_PATCH = _dispatch_command

    def _parts(self) -> list[str]:
        return [unquote(p) for p in self.path.split("?", 1)[0].split("/") if p]

    def _dispatch(self, method: str) -> None:
        path, _, query = self.path.partition("?")
        q = {k: v[-1] for k, v in parse_qs(query).items()}
        parts = self._parts()
        self._bad_framing = False
        try:
            self._unread = self._declared_length() or 0
        except _Refused as exc:  # unknown body length: answer, drain a little, close
            self._unread = 1 << 16
            self._json({"error": str(exc)}, exc.status)
            self._linger()
            return
        try:
            if method == "OPTIONS":
                raise _Refused(403, "cross-origin requests are not allowed.")
            if method not in ("GET", "POST"):
                raise _Refused(405, f"method {method} not allowed.", {"Allow": "GET, HEAD, POST"})
            self._precheck(parts)
            if method == "GET" and parts == ["favicon.ico"]:
                self._send(204, b"", "image/x-icon")
            elif method == "GET" and (not parts or parts[0] == "static"):
                self._static(parts[1:] if parts else ["index.html"])
            elif parts and parts[0] == "api":
                self._api(method, parts[1:], q)
            else:
                self._json({"error": f"not found: {path}"}, 404)
        except _Refused as exc:
            self._json({"error": str(exc)}, exc.status, exc.headers)
        except (TimeoutError, ConnectionError):
            self.close_connection = True
            self._unread = 0
            return
        except ViewerBusyError as exc:
            self._json({"error": str(exc)}, 429, {"Retry-After": "1"})
        except (SpectrageoError, ValueError) as exc:
            self._json({"error": str(exc)}, 400)
        except Exception as exc:  # noqa: BLE001 - the server must stay up
            if os.environ.get("SPECTRAGEO_DEBUG"):
                traceback.print_exc()
            self._json({"error": _error_text(exc)}, 500)
        if self._unread:
            self._linger()

    def _precheck(self, parts: list[str]) -> None:
        """Request target and Host for everything; same origin and the session token for the API."""
        if not self.path.startswith("/"):  # absolute-form ("http://host/..."), "*", authority
            raise _Refused(400, "the request target must be a path starting with '/'.")
        self._check_host()
        if not parts or parts[0] != "api":
            return
        origin = self.headers.get("Origin")
        if origin is not None and origin.strip().lower() not in self._origins():
            raise _Refused(403, "cross-origin request refused.")
        site = (self.headers.get("Sec-Fetch-Site") or "").strip().lower()
        if site and site not in ("same-origin", "none"):
            raise _Refused(403, f"cross-site request refused (Sec-Fetch-Site: {site[:20]}).")
        token = self.headers.get(TOKEN_HEADER) or ""
        if not (self.token and hmac.compare_digest(token.encode(), self.token.encode())):
            raise _Refused(403, f"missing or wrong {TOKEN_HEADER} header (reload the viewer page).")

    def _origins(self) -> set[str]:
        port = self.server.server_address[1]
        return {f"http://{h}:{port}" for h in ("127.0.0.1", "localhost", "[::1]")}

    def _check_host(self) -> None:
        """Exactly one ``Host: host[:port]`` naming the loopback (none only in HTTP/1.0): 400 when
        malformed or repeated, 403 for another host (DNS rebinding)."""
        values = self.headers.get_all("Host") or []
        if len(values) > 1:
            raise _Refused(400, f"the request has {len(values)} Host headers; send exactly one.")
        if not values:
            if self.request_version == "HTTP/1.0":
                return
            raise _Refused(400, "the request needs a Host header.")
        m = _HOST.fullmatch(values[0].strip())
        if m is None or (m["port"] is not None and int(m["port"]) > 65535):
            raise _Refused(400, f"malformed Host header {values[0].strip()[:60]!r}.")
        if m["v6"] is not None:
            try:
                ok = ipaddress.IPv6Address(m["v6"]) == ipaddress.IPv6Address("::1")
            except ValueError:
                raise _Refused(400, f"malformed Host header {values[0].strip()[:60]!r}.") from None
        else:
            ok = m["name"].lower() in LOOPBACK_NAMES
        if not ok:
            raise _Refused(403, "forbidden host")

    def _static(self, parts: list[str]) -> None:
        p = (STATIC_DIR / "/".join(parts)).resolve()
        if STATIC_DIR not in p.parents and p != STATIC_DIR or not p.is_file():
            self._json({"error": "not found"}, 404)
            return
        ctype = mimetypes.guess_type(p.name)[0] or "application/octet-stream"
        if p.suffix == ".js":
            ctype = "text/javascript"
        body, headers = p.read_bytes(), {}
        if p.suffix == ".html":
            headers["Content-Security-Policy"] = _index_csp(body)
            body = body.replace(TOKEN_PLACEHOLDER, self.token.encode("ascii"))
            ctype = "text/html; charset=utf-8"
        self._send(200, body, ctype, headers)

    def _api(self, method: str, parts: list[str], q: dict) -> None:
        s = self.session
        route = (method, parts[0] if parts else "")
        if route == ("GET", "state"):
            self._json(_state(s))
        elif route == ("POST", "upload"):
            name = clean_name(q.get("name", "upload"))
            with self._upload_slot():
                p = self._receive(file_suffix(name))
                try:
                    m = s.load_file(p, name)
                finally:
                    p.unlink(missing_ok=True)
            self._json({"model": m.info()})
        elif route == ("POST", "field-upload"):
            m = s.get(q.get("model", ""))
            name = clean_name(q.get("name", "field.txt"), default="field.txt")
            with self._upload_slot():
                p = self._receive("")
                try:
                    fname = s.attach_field_file(m, p, name)
                finally:
                    p.unlink(missing_ok=True)
            self._json({"field": fname, "model": m.info()})
        elif route == ("GET", "job") and len(parts) == 2:
            self._json(s.job(parts[1]).to_json())
        elif route == ("POST", "compare"):
            p = self._params()
            a, b = s.get(str(p.get("a"))), s.get(str(p.get("b")))
            job = s.start("compare", lambda j: s.compare(a, b, p.get("frame", 0), j), (a, b))
            self._json({"job": job.id})
        elif parts and parts[0] == "model" and len(parts) >= 2:
            self._model(method, s.get(parts[1]), parts[2:], q)
        else:
            self._json({"error": f"no such API: {method} /api/{'/'.join(parts)}"}, 404)

    def _upload_slot(self):
        sem = self.upload_slots

        class _Slot:
            def __enter__(slot):
                if not sem.acquire(blocking=False):
                    raise _Refused(
                        429,
                        f"too many uploads at once (at most {self.limits.max_uploads}); "
                        "try again when one has finished.",
                        {"Retry-After": "1"},
                    )

            def __exit__(slot, *exc):
                sem.release()

        return _Slot()

    def _model(self, method: str, m: Model, rest: list[str], q: dict) -> None:
        s = self.session
        what = rest[0] if rest else ""
        if method == "GET":
            if what == "":
                self._json(m.info())
            elif what == "positions":
                V, _, _ = m.geometry(q.get("frame", 0))
                self._array(np.asarray(V, dtype=np.float32))
            elif what == "faces":
                _, F, _ = m.geometry(0)
                self._array(np.zeros((0, 3), np.uint32) if F is None else F.astype(np.uint32))
            elif what == "lod":
                self._json(s.lod(m, q.get("max_faces", 100_000), q.get("max_points", 150_000)))
            elif what == "array" and len(rest) == 2:
                if rest[1] not in m.arrays:
                    raise InvalidInputError(f"unknown array {rest[1]!r}.")
                self._array(m.arrays[rest[1]])
            elif what == "download":
                data, name = s.download(m, q.get("format", _ext(m)))
                self._send(
                    200,
                    data,
                    "application/octet-stream",
                    {"Content-Disposition": content_disposition(name)},
                )
            else:
                self._json({"error": f"no such API: GET model/{what}"}, 404)
            return
        p = self._params()
        frame = p.get("frame", 0)
        if what == "features":
            job = s.start("features", lambda j: s.features(m, p.get("patch", 15), frame, j), [m])
        elif what == "curves":
            job = s.start(
                "feature curves", lambda j: s.curves(m, p.get("patch", 15), frame, j), [m]
            )
        elif what == "scalar":
            job = s.start("heatmap", lambda j: s.scalar(m, str(p.get("field", "")), frame, j), [m])
        elif what == "denoise":
            job = s.start("denoising", lambda j: s.denoise(m, p.get("method", "tsgsp"), j), [m])
        elif what == "outliers":
            job = s.start(
                "outlier removal",
                lambda j: s.outliers(m, p.get("method", "rpca"), p.get("k", 10), j),
                [m],
            )
        elif what == "fill-holes":
            job = s.start(
                "hole filling",
                lambda j: s.fill_holes(
                    m, p.get("method", "lsm"), p.get("max_hole"), j, p.get("density", 1.0)
                ),
                [m],
            )
        else:
            self._json({"error": f"no such API: POST model/{what}"}, 404)
            return
        self._json({"job": job.id})


def _state(s: ViewerSession) -> dict:
    from .. import denoise, io

    try:
        dens = [{"name": n, "summary": denoise.get(n).summary} for n in denoise.available()]
    except Exception:  # noqa: BLE001 - a broken plugin must not take the viewer down
        dens = []
    return {
        "models": [m.info() for m in list(s.models.values())],
        "denoisers": dens,
        "outlier_methods": _outlier_methods(),
        "hole_methods": _hole_methods(),
        "formats": io.supported_formats(),
        "limits": s.limits.to_json(),
        "feature_method": _analysis.SALIENCY_SOURCE
        if _analysis._saliency_fn("feature_vertices")
        else _analysis.FEATURE_SOURCE,
    }


def _hole_methods() -> list[str]:
    from ..complete import INPAINT_METHODS

    return ["lsm", *[x for x in INPAINT_METHODS if x != "lsm"]]  # the default first


def _outlier_methods() -> list[str]:
    from .. import outliers

    names = getattr(outliers, "METHODS", None)
    if names:
        return list(names)
    return ["rpca"]


class _HTTPServer(ThreadingHTTPServer):
    """Threaded server: a thread per connection, at most ``max_connections`` of them; a request's
    line and headers must arrive within a deadline, and when the server is full, connections that
    have waited ``IDLE_GRACE_S`` for a request give way to new ones (oldest first)."""

    daemon_threads = True
    block_on_close = False
    request_queue_size = 128  # listen backlog: a burst of connections waits in no SYN retries

    def __init__(self, address, handler, *, max_connections: int):
        super().__init__(address, handler)
        self.max_connections = max_connections
        self._active = 0
        self._lock = threading.Lock()
        self._deadlines: dict[socket.socket, float] = {}  # connections waiting for a request
        self._waiting_since: dict[socket.socket, float] = {}
        self._evicted: set[socket.socket] = set()  # closed by us, their threads ending
        self._conns: dict[socket.socket, threading.Thread] = {}
        self._closed = threading.Event()
        self._reaper = threading.Thread(target=self._reap, daemon=True, name="spectrageo-reaper")
        self._reaper.start()

    @property
    def active_connections(self) -> int:
        return self._active

    def process_request(self, request, client_address):
        with self._lock:
            full = self._active - len(self._evicted) >= self.max_connections
            victim = self._idle_victim_locked() if full else None
            if victim is not None:
                self._evicted.add(victim)
                self._deadlines.pop(victim, None)
                self._waiting_since.pop(victim, None)
            if not full or victim is not None:
                self._active += 1
        if victim is not None:
            _shutdown(victim)
        elif full:
            self._refuse(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            with self._lock:
                self._active -= 1
            raise

    def _idle_victim_locked(self):
        old = time.monotonic() - IDLE_GRACE_S
        idle = [(t, id(s), s) for s, t in self._waiting_since.items() if t <= old]
        return min(idle)[2] if idle else None

    def process_request_thread(self, request, client_address):
        with self._lock:
            self._conns[request] = threading.current_thread()
        try:
            super().process_request_thread(request, client_address)
        finally:
            with self._lock:
                self._active -= 1
                self._deadlines.pop(request, None)
                self._waiting_since.pop(request, None)
                self._evicted.discard(request)
                self._conns.pop(request, None)

    def _refuse(self, request) -> None:
        body = b'{"error": "too many connections; try again"}'
        head = (
            b"HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\n"
            b"Content-Length: %d\r\nRetry-After: 1\r\nConnection: close\r\n\r\n" % len(body)
        )
        try:
            request.settimeout(1.0)
            request.sendall(head + body)
        except OSError:
            pass
        self.shutdown_request(request)

    def watch(self, sock, seconds: float) -> None:
        with self._lock:
            now = time.monotonic()
            self._deadlines[sock] = now + seconds
            self._waiting_since[sock] = now

    def unwatch(self, sock) -> None:
        with self._lock:
            self._deadlines.pop(sock, None)
            self._waiting_since.pop(sock, None)

    def _reap(self) -> None:
        while not self._closed.wait(0.2):
            now = time.monotonic()
            with self._lock:
                late = [s for s, t in self._deadlines.items() if t < now]
                for s in late:
                    del self._deadlines[s]
                    self._waiting_since.pop(s, None)
            for s in late:
                _shutdown(s)

    def close_connections(self, timeout: float) -> bool:
        """Shut every open connection down and wait up to ``timeout`` s for their threads;
        whether they all ended."""
        with self._lock:
            conns = dict(self._conns)
        for s in conns:
            _shutdown(s)
        end = time.monotonic() + timeout
        for t in conns.values():
            if t is not threading.current_thread():
                t.join(max(end - time.monotonic(), 0.0))
        return not any(t.is_alive() for t in conns.values() if t is not threading.current_thread())

    def server_close(self):
        self._closed.set()
        super().server_close()


def _shutdown(sock: socket.socket) -> None:
    try:
        sock.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
