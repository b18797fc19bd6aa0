"""Local web server of the viewer: a JSON API plus raw binary arrays, on the loopback interface only.

The browser side (``static/``) renders with three.js; this module only reads files, runs the library
functions and hands out arrays. Bulk data travels as raw little-endian buffers (positions float32,
faces uint32, masks uint8/int8, colours uint8 RGB), so a 500k-vertex mesh is about 12 MB of
positions and faces and needs no JSON parsing in the browser.

API (every JSON answer is an object; errors are ``{"error": message}`` with status 4xx/5xx):

========================================  =====================================================
``GET  /api/state``                       loaded models, denoisers, outlier methods, formats
``POST /api/upload?name=FILE``            body: the file bytes; reads it with :func:`spectrageo.io.read`
``POST /api/field-upload?model=ID&name=``  body: ``.npy``/``.txt``/``.csv`` scalars (per vertex or face)
``GET  /api/model/ID``                    model information
``GET  /api/model/ID/positions?frame=T``  float32 (n, 3) of frame ``T``
``GET  /api/model/ID/faces``              uint32 (m, 3) (empty for point clouds)
``GET  /api/model/ID/array/KEY``          a computed array (dtype in the ``X-Dtype`` header)
``GET  /api/model/ID/lod?max_faces=N``     level-of-detail proxy (``reps``/``faces`` array keys)
``GET  /api/model/ID/download?format=.ply`` the model written with :func:`spectrageo.io.write`
``POST /api/model/ID/features``           ``{"patch": 15, "frame": 0}`` -> job
``POST /api/model/ID/curves``             ``{"patch": 15, "frame": 0}`` -> job
``POST /api/model/ID/scalar``             ``{"field": "saliency" | "curvature" | "attr:NAME" ...}`` -> job
``POST /api/model/ID/denoise``            ``{"method": "tsgsp"}`` -> job, result is a new model
``POST /api/model/ID/outliers``           ``{"method": "rpca", "k": 10}`` -> job, result is a new model
``POST /api/model/ID/fill-holes``         ``{"method": "lsm", "max_hole": null, "density": 1}`` -> job, new model
``POST /api/compare``                     ``{"a": ID, "b": ID, "frame": 0}`` -> job (metrics table)
``GET  /api/job/JOB``                     ``{"state", "progress", "message", "elapsed", "result"|"error"}``
========================================  =====================================================

Security model (see :class:`ViewerLimits` for the limits):

* The server listens on ``127.0.0.1`` only and answers only ``Host`` names of the loopback
  interface (a guard against DNS rebinding).
* Every ``/api/`` request, reads included, must carry the per-session token in the
  ``X-Spectrageo-Token`` header. The token is random, made when the server starts, and written into
  ``index.html`` when the page is served; another origin cannot read it. A custom header also makes
  every cross-origin ``fetch`` send a CORS preflight, which the server refuses (``OPTIONS`` -> 403,
  no ``Access-Control-Allow-*`` header is ever sent). Requests whose ``Origin`` is not the server's
  own, or whose ``Sec-Fetch-Site`` is ``cross-site``/``same-site``, are refused with 403 before the
  body is read, so nothing happens.
* Names of uploaded files are data: NFC-normalised, control characters removed, at most
  :data:`MAX_NAME` characters (extension kept); files go to disk under a generated name, and a name
  in a ``Content-Disposition`` header is percent-encoded (RFC 6266) with an ASCII fallback.
* Bodies are bounded before they are read (``413``), uploads are streamed to a private temporary
  folder, jobs run on a bounded pool (``429`` beyond it), models beyond a count/byte budget are
  unloaded least-recently-used first, slow or idle connections time out, and the temporary folder
  is removed on exit (stale ones of dead viewer processes at start).
"""

from __future__ import annotations

import atexit
import base64
import functools
import hashlib
import hmac
import itertools
import json
import mimetypes
import os
import queue
import re
import secrets
import shutil
import socket
import stat
import tempfile
import threading
import time
import traceback
import unicodedata
import uuid
from dataclasses import dataclass, field, fields, replace
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, quote, unquote, urlsplit

import numpy as np

from .._errors import InvalidInputError, SpectrageoError
from .._validation import check_choice, check_positive
from . import _analysis

STATIC_DIR = Path(__file__).resolve().parent / "static"
TOKEN_HEADER = "X-Spectrageo-Token"
TOKEN_PLACEHOLDER = b"__SPECTRAGEO_TOKEN__"
TMP_PREFIX = "spectrageo-view-"
MAX_NAME = 200  # characters of a model name (longer ones are cut, keeping the extension)
MAX_JSON_BODY = 1 << 20  # bytes of a JSON request body
CHUNK = 1 << 20  # bytes per read while streaming an upload to disk
LINGER_S = 1.0  # at most this long and ...
LINGER_BYTES = 16 << 20  # ... this much of an unread body is drained after a refusal, so that
# the client can read the answer before the connection is reset
ENV_PREFIX = "SPECTRAGEO_VIEW_"


# --------------------------------------------------------------------------- limits
@dataclass(frozen=True)
class ViewerLimits:
    """Resource limits of one viewer server.

    Every field can also be set with an environment variable ``SPECTRAGEO_VIEW_<FIELD>`` (for
    example ``SPECTRAGEO_VIEW_MAX_UPLOAD_MB=1024``); explicit arguments win over the environment.

    Parameters
    ----------
    max_upload_mb : float
        Largest accepted request body of an upload, in MiB (``spectrageo view --max-upload``).
        Larger ones are refused from their ``Content-Length`` before a byte is read (413).
    max_models : int
        Models kept loaded; beyond it the least recently used one is unloaded
        (``--max-models``).
    max_memory_mb : float
        Budget of the models' arrays (geometry and everything computed for it), in MiB; beyond it
        least-recently-used models are unloaded, never the newest nor one a job is using
        (``--max-memory``).
    max_jobs : int
        Computations running at once.
    max_queued : int
        Computations waiting for a worker; further requests get 429 with a JSON error.
    max_uploads : int
        Uploads received and read at once; further ones get 429 before their body is read.
    request_timeout : float
        Seconds to receive a request's headers (idle keep-alive connections included) and the
        longest pause while receiving a body; the connection is closed after it.
    max_connections : int
        Open connections at once; further ones get 503 and are closed.
    """

    max_upload_mb: float = 256.0
    max_models: int = 32
    max_memory_mb: float = 2048.0
    max_jobs: int = 2
    max_queued: int = 8
    max_uploads: int = 2
    request_timeout: float = 30.0
    max_connections: int = 64

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.type == "int":
                ok = isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1
                want = "an integer >= 1"
            else:
                ok = isinstance(v, (int, float, np.number)) and not isinstance(v, bool) and v > 0
                ok = ok and np.isfinite(v)
                want = "a number > 0"
            if not ok:
                raise InvalidInputError(f"`{f.name}` must be {want}; got {v!r}.")

    @classmethod
    def from_env(cls, environ=None, **overrides) -> ViewerLimits:
        """Defaults, then ``SPECTRAGEO_VIEW_*`` environment variables, then ``overrides``."""
        env = os.environ if environ is None else environ
        values: dict[str, Any] = {}
        for f in fields(cls):
            raw = env.get(ENV_PREFIX + f.name.upper())
            if raw is None or raw.strip() == "":
                continue
            try:
                values[f.name] = int(raw) if f.type == "int" else float(raw)
            except ValueError:
                raise InvalidInputError(
                    f"`{ENV_PREFIX}{f.name.upper()}` must be a number; got {raw!r}."
                ) from None
        values.update({k: v for k, v in overrides.items() if v is not None})
        unknown = set(values) - {f.name for f in fields(cls)}
        if unknown:
            raise InvalidInputError(f"unknown viewer limit(s): {', '.join(sorted(unknown))}.")
        return cls(**values)

    @property
    def max_upload_bytes(self) -> int:
        return int(self.max_upload_mb * 2**20)

    @property
    def max_memory_bytes(self) -> int:
        return int(self.max_memory_mb * 2**20)

    def to_json(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)} | {
            "max_upload_bytes": self.max_upload_bytes
        }


# --------------------------------------------------------------------------- names
_SPLIT_PATH = re.compile(r"[/\\]")
_EXT = re.compile(r"(\.[A-Za-z0-9]{1,10})?(\.[A-Za-z0-9]{1,10})$")
_ASCII_UNSAFE = re.compile(r"[^A-Za-z0-9._+-]+")


def clean_name(name, *, default: str = "upload", max_len: int = MAX_NAME) -> str:
    """A file name fit for display and JSON: NFC, no control characters, no folders, bounded.

    Unicode is kept. Control and format characters (``Cc``, ``Cf``, ``Cs``: CR, LF, NUL, bidi
    overrides) are removed, line/paragraph separators become spaces, everything up to the last
    ``/`` or ``\\`` is dropped, and names longer than ``max_len`` characters are cut in the stem
    (with an ellipsis) so that the extension, which selects the reader, survives.
    """
    s = unicodedata.normalize("NFC", str(name))
    s = "".join(
        " " if unicodedata.category(c) in ("Zl", "Zp") else c
        for c in s
        if unicodedata.category(c) not in ("Cc", "Cf", "Cs")
    )
    s = _SPLIT_PATH.split(s)[-1].strip()
    if s in ("", ".", ".."):
        return default
    if len(s) > max_len:
        ext = file_suffix(s)
        s = s[: max_len - len(ext) - 1].rstrip() + "\u2026" + ext
    return s


def file_suffix(name: str) -> str:
    """Lower-case extension that selects the reader: ``'.ply'``, ``'.ply.gz'``, or ``''``."""
    m = _EXT.search(name)
    if not m:
        return ""
    if m.group(2).lower() == ".gz" and m.group(1):
        return (m.group(1) + m.group(2)).lower()
    return m.group(2).lower()


def _stem(name: str) -> str:
    ext = file_suffix(name)
    return name[: len(name) - len(ext)] if ext and len(ext) < len(name) else name


def content_disposition(name: str) -> str:
    """``attachment`` header value for ``name`` (RFC 6266): ASCII fallback + UTF-8 ``filename*``."""
    name = clean_name(name, default="download")
    fallback = unicodedata.normalize("NFKD", name).encode("ascii", "ignore").decode("ascii")
    fallback = _ASCII_UNSAFE.sub("_", fallback).strip("_") or "download"
    if not fallback.lower().endswith(file_suffix(name)):
        fallback += file_suffix(name)
    return f"attachment; filename=\"{fallback}\"; filename*=UTF-8''{quote(name, safe='')}"


def _header_value(v) -> str:
    """A header value without CR/LF (defence in depth: no header is ever built from raw input)."""
    return re.sub(r"[\r\n\x00]+", " ", str(v))


# --------------------------------------------------------------------------- temporary folders
def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # exists, belongs to someone else
    except OSError:
        return True
    return True


def remove_stale_temp_dirs(root: str | os.PathLike | None = None) -> list[Path]:
    """Remove ``spectrageo-view-<PID>-*`` folders of viewer processes that are gone.

    Only folders owned by the current user are touched; folders of a live PID (or this process)
    are kept. Folders of the old naming (no PID) are removed when untouched for an hour. Returns
    the removed paths. Does nothing on Windows (no cheap, safe liveness test).
    """
    if os.name == "nt":
        return []
    root = Path(root if root is not None else tempfile.gettempdir())
    removed = []
    pat = re.compile(re.escape(TMP_PREFIX) + r"(\d+)-[A-Za-z0-9_]+")
    try:
        candidates = list(root.glob(TMP_PREFIX + "*"))
    except OSError:
        return []
    for p in candidates:
        try:
            st = os.lstat(p)
        except OSError:
            continue
        if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid():
            continue
        m = pat.fullmatch(p.name)
        if m:
            pid = int(m.group(1))
            if pid == os.getpid() or _pid_alive(pid):
                continue
        elif time.time() - st.st_mtime < 3600:
            continue
        shutil.rmtree(p, ignore_errors=True)
        if not p.exists():
            removed.append(p)
    return removed


def _make_temp_dir() -> Path:
    return Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{os.getpid()}-"))


# --------------------------------------------------------------------------- compression bombs
def _check_expansion(path: Path, name: str, cap: int) -> None:
    """Refuse a gzip or zip upload that expands beyond ``cap`` bytes (the models' memory budget).

    gzip is decompressed as a stream and counted (bounded memory, nothing kept); for zip archives
    (``.npz``, ``.3mf``) the sizes declared in the central directory are summed. The readers of
    :mod:`spectrageo.io` bound what they decode on their own; this check only answers early.
    """
    import gzip
    import zipfile
    import zlib

    with open(path, "rb") as f:
        magic = f.read(4)
    too_big = f"{name} decompresses to more than {cap / 2**20:g} MB (the viewer's --max-memory)."
    try:
        if magic[:2] == b"\x1f\x8b":
            n = 0
            with gzip.open(path, "rb") as g:
                while chunk := g.read(CHUNK):
                    n += len(chunk)
                    if n > cap:
                        raise InvalidInputError(too_big)
        elif magic == b"PK\x03\x04":
            with zipfile.ZipFile(path) as z:
                if sum(i.file_size for i in z.infolist()) > cap:
                    raise InvalidInputError(too_big)
    except (OSError, EOFError, zlib.error, zipfile.BadZipFile) as exc:
        raise InvalidInputError(
            f"could not read {name}: corrupt compressed data ({exc})."
        ) from None


# --------------------------------------------------------------------------- models
_TICK = itertools.count()  # recency of model use (LRU eviction)


def _nbytes(obj, depth: int = 0, seen: set | None = None) -> int:
    """Bytes of the numpy arrays reachable from ``obj`` (dataclass fields, dicts, lists)."""
    seen = set() if seen is None else seen
    if id(obj) in seen or depth > 4:
        return 0
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        return int(obj.nbytes)
    if isinstance(obj, dict):
        return sum(_nbytes(v, depth + 1, seen) for v in list(obj.values()))
    if isinstance(obj, (list, tuple)):
        return sum(_nbytes(v, depth + 1, seen) for v in obj)
    d = getattr(obj, "__dict__", None)
    if isinstance(d, dict):
        return sum(_nbytes(v, depth + 1, seen) for v in list(d.values()))
    return 0


@dataclass
class Model:
    """One loaded geometry and the arrays computed for it."""

    id: str
    name: str
    obj: Any
    source: str = ""
    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    fields: dict[str, np.ndarray] = field(default_factory=dict)  # user scalar fields
    last_used: int = field(default_factory=lambda: next(_TICK), repr=False)
    pins: int = field(default=0, repr=False)  # running jobs using the model (never evicted)
    obj_bytes: int = field(default=0, repr=False)

    @property
    def nbytes(self) -> int:
        """Bytes of the geometry plus every array computed for it."""
        arr = sum(int(a.nbytes) for a in list(self.arrays.values()))
        return self.obj_bytes + arr + sum(int(a.nbytes) for a in list(self.fields.values()))

    @property
    def kind(self) -> str:
        from ..geometry import Mesh, MeshAnimation, PointCloud

        if isinstance(self.obj, Mesh):
            return "mesh"
        if isinstance(self.obj, PointCloud):
            return "points"
        if isinstance(self.obj, MeshAnimation):
            return "animation"
        return "sequence"

    @property
    def n_frames(self) -> int:
        return 1 if self.kind in ("mesh", "points") else int(self.obj.n_frames)

    def frame_index(self, frame) -> int:
        try:
            t = int(frame or 0)
        except (TypeError, ValueError):
            raise InvalidInputError(f"`frame` must be an integer; got {frame!r}.") from None
        if not 0 <= t < self.n_frames:
            raise InvalidInputError(f"`frame` must be in [0, {self.n_frames - 1}]; got {t}.")
        return t

    def geometry(self, frame=0):
        """(V (n,3) float64, F (m,3) int64 or None, normals or None) of a frame."""
        t = self.frame_index(frame)
        o, k = self.obj, self.kind
        if k == "mesh":
            return o.vertices, o.faces, None
        if k == "points":
            return o.points, None, o.normals
        if k == "animation":
            return np.asarray(o.frames[t], dtype=np.float64), o.faces, None
        pc = o[t]
        return pc.points, None, pc.normals

    def attribute_names(self) -> list[str]:
        o, k = self.obj, self.kind
        names = []
        if k == "mesh":
            names += [f"attr:{a}" for a in (o.vertex_attributes or {})]
            names += [f"face:{a}" for a in (o.face_attributes or {})]
        elif k == "points":
            names += [f"attr:{a}" for a in (o.attributes or {})]
        names += [f"field:{a}" for a in self.fields]
        return names

    def info(self) -> dict:
        V, F, _ = self.geometry(0)
        lo, hi = V.min(axis=0), V.max(axis=0)
        fields = ["curvature"]
        if F is not None:
            fields = ["saliency", "saliency-combined", "curvature"]
        fields += ["feature-class"] + self.attribute_names()
        return {
            "id": self.id,
            "name": self.name,
            "kind": self.kind,
            "n_vertices": int(V.shape[0]),
            "n_faces": 0 if F is None else int(F.shape[0]),
            "n_frames": self.n_frames,
            "bbox": [lo.tolist(), hi.tolist()],
            "fields": fields,
            "source": self.source,
        }


# --------------------------------------------------------------------------- jobs
class Job:
    """A background computation with progress, polled by the browser.

    ``state`` is ``"running"`` from submission (``queued`` tells whether it still waits for a
    worker), then ``"done"`` or ``"error"``.
    """

    def __init__(self, desc: str):
        self.id = uuid.uuid4().hex[:12]
        self.desc = desc
        self.state = "running"
        self.queued = True
        self.progress: float | None = None
        self.message = f"{desc}: waiting for a free worker"
        self.result: dict | None = None
        self.error: str | None = None
        self.started = time.perf_counter()
        self.finished: float | None = None

    def update(self, progress: float | None = None, message: str | None = None) -> None:
        if progress is not None:
            self.progress = float(min(max(progress, 0.0), 1.0))
        if message is not None:
            self.message = message

    def to_json(self) -> dict:
        end = self.finished if self.finished is not None else time.perf_counter()
        d = {
            "id": self.id,
            "state": self.state,
            "queued": self.queued,
            "progress": self.progress,
            "message": self.message,
            "elapsed": round(end - self.started, 3),
        }
        if self.result is not None:
            d["result"] = self.result
        if self.error is not None:
            d["error"] = self.error
        return d


class ViewerBusyError(SpectrageoError):
    """The job queue is full (HTTP 429); viewer-internal, the library never raises it."""


class _JobPool:
    """``workers`` daemon threads and at most ``queued`` waiting jobs (submit fails beyond)."""

    def __init__(self, workers: int, queued: int):
        self.workers = workers
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._slots = threading.BoundedSemaphore(workers + queued)
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()
        self._closed = False

    def submit(self, fn) -> bool:
        with self._lock:
            if self._closed or not self._slots.acquire(blocking=False):
                return False
            if len(self._threads) < self.workers:
                t = threading.Thread(
                    target=self._loop,
                    daemon=True,
                    name=f"spectrageo-view-worker-{len(self._threads)}",
                )
                self._threads.append(t)
                t.start()
        self._q.put(fn)
        return True

    def _loop(self) -> None:
        while True:
            fn = self._q.get()
            if fn is None:
                return
            try:
                fn()
            finally:
                self._slots.release()

    def close(self) -> None:
        with self._lock:
            self._closed = True
            for _ in self._threads:
                self._q.put(None)


def _error_text(exc: BaseException) -> str:
    if isinstance(exc, (SpectrageoError, ValueError)):
        return str(exc)
    return f"internal error: {type(exc).__name__}: {exc}"


# --------------------------------------------------------------------------- session
class ViewerSession:
    """The models and jobs of one viewer server (thread-safe).

    Parameters
    ----------
    limits : ViewerLimits, optional
        Model budget and job pool bounds (defaults: :class:`ViewerLimits`).
    tmp_dir : path-like, optional
        Private folder for temporary files; without it each call makes and removes its own.
    """

    MAX_FINISHED_JOBS = 256

    def __init__(self, limits: ViewerLimits | None = None, *, tmp_dir=None):
        self.limits = limits or ViewerLimits()
        self.tmp_dir = None if tmp_dir is None else Path(tmp_dir)
        self._lock = threading.Lock()
        self.models: dict[str, Model] = {}
        self.jobs: dict[str, Job] = {}
        self.evicted: dict[str, str] = {}  # id -> name of unloaded models (for the error message)
        self._counter = 0
        self._pool = _JobPool(self.limits.max_jobs, self.limits.max_queued)

    def close(self) -> None:
        """Stop the job workers (a running computation finishes in its daemon thread)."""
        self._pool.close()

    # ---- models
    def add(self, obj, name: str, source: str = "") -> Model:
        size = _nbytes(obj)
        with self._lock:
            self._counter += 1
            mid = f"m{self._counter}"
            m = Model(mid, clean_name(name, default=mid), obj, source, obj_bytes=size)
            self.models[mid] = m
            self._trim_locked(keep=mid)
        return m

    @property
    def nbytes(self) -> int:
        """Bytes held by the loaded models."""
        return sum(m.nbytes for m in list(self.models.values()))

    def trim(self) -> list[str]:
        """Unload least-recently-used models beyond ``max_models`` / ``max_memory_mb``."""
        with self._lock:
            return self._trim_locked()

    def _trim_locked(self, keep: str | None = None) -> list[str]:
        out = []
        budget = self.limits.max_memory_bytes
        if keep is None and self.models:  # never the most recently used one
            keep = max(self.models.values(), key=lambda m: m.last_used).id
        while True:
            total = sum(m.nbytes for m in self.models.values())
            if len(self.models) <= self.limits.max_models and total <= budget:
                break
            victims = [m for m in self.models.values() if m.id != keep and m.pins == 0]
            if not victims:
                break
            v = min(victims, key=lambda m: m.last_used)
            del self.models[v.id]
            self.evicted[v.id] = v.name
            out.append(v.id)
        while len(self.evicted) > 4096:
            self.evicted.pop(next(iter(self.evicted)))
        return out

    def _scratch(self) -> tuple[Path, bool]:
        """(folder for temporary files, whether the caller must remove it)."""
        if self.tmp_dir is not None and self.tmp_dir.is_dir():
            return self.tmp_dir, False
        return _make_temp_dir(), True

    def load_path(self, path: str | os.PathLike, name: str | None = None) -> Model:
        from .. import io

        p = Path(path)
        obj = io.read(p)
        return self.add(obj, name or p.name, source=str(p))

    def load_file(self, path: str | os.PathLike, name: str) -> Model:
        """Read an uploaded file saved at ``path``; ``name`` is the user's name of it."""
        from .. import io

        name = clean_name(name)
        _check_expansion(Path(path), name, self.limits.max_memory_bytes)
        try:
            obj = io.read(Path(path))
        except Exception as exc:  # noqa: BLE001 - any reader failure is a bad upload
            text = str(exc) if isinstance(exc, SpectrageoError) else f"{type(exc).__name__}: {exc}"
            text = text.replace(str(path), name).replace(Path(path).name, name)
            raise InvalidInputError(f"could not read {name}: {text}") from exc
        return self.add(obj, name, source="upload")

    def load_bytes(self, data: bytes, name: str) -> Model:
        """Read an uploaded file; the name (its extension) selects the reader."""
        folder, own = self._scratch()
        p = folder / f"upload-{uuid.uuid4().hex}{file_suffix(clean_name(name))}"
        try:
            p.write_bytes(data)
            return self.load_file(p, name)
        finally:
            p.unlink(missing_ok=True)
            if own:
                shutil.rmtree(folder, ignore_errors=True)

    def get(self, mid: str) -> Model:
        with self._lock:
            m = self.models.get(mid)
            if m is not None:
                m.last_used = next(_TICK)
                return m
            gone = self.evicted.get(mid)
        if gone is not None:
            lim = self.limits
            raise InvalidInputError(
                f"model {mid!r} ({gone}) was unloaded to stay within the viewer's budget "
                f"({lim.max_models} models, {lim.max_memory_mb:g} MB; see --max-models and "
                "--max-memory); load it again."
            )
        raise InvalidInputError(f"unknown model {mid!r}.")

    # ---- jobs
    def start(self, desc: str, fn, models=()) -> Job:
        """Run ``fn(job) -> dict`` on the job pool; its dict becomes the job's result.

        ``models`` are kept loaded while the job runs. Raises :class:`ViewerBusyError` when
        ``max_jobs`` jobs run and ``max_queued`` wait already.
        """
        job = Job(desc)
        models = tuple(models)

        def run():
            job.queued = False
            job.message = desc
            try:
                job.result = fn(job)
                job.progress = 1.0
                job.state = "done"
                job.message = f"{desc}: done"
            except BaseException as exc:  # noqa: BLE001 - reported to the browser
                if os.environ.get("SPECTRAGEO_DEBUG"):
                    traceback.print_exc()
                job.error = _error_text(exc)
                job.state = "error"
                job.message = f"{desc}: {job.error}"
            finally:
                job.finished = time.perf_counter()
                with self._lock:
                    for m in models:
                        m.pins -= 1
                    self._trim_locked()

        with self._lock:
            for m in models:
                m.pins += 1
            self.jobs[job.id] = job
            self._prune_jobs_locked()
        if not self._pool.submit(run):
            with self._lock:
                for m in models:
                    m.pins -= 1
                self.jobs.pop(job.id, None)
            lim = self.limits
            raise ViewerBusyError(
                f"the viewer is busy ({lim.max_jobs} jobs running, {lim.max_queued} waiting); "
                "try again when one has finished."
            )
        return job

    def _prune_jobs_locked(self) -> None:
        done = [j for j in self.jobs.values() if j.finished is not None]
        for j in done[: max(0, len(done) - self.MAX_FINISHED_JOBS)]:
            del self.jobs[j.id]

    def job(self, jid: str) -> Job:
        j = self.jobs.get(jid)
        if j is None:
            raise InvalidInputError(f"unknown job {jid!r}.")
        return j

    def features(self, m: Model, patch, frame, job: Job | None = None) -> dict:
        patch = _as_int(patch, "patch", 3)
        V, F, N = m.geometry(frame)
        if job:
            job.update(0.1, f"classifying {len(V)} vertices (patch {patch})")
        mask, method = _analysis.feature_vertices(V, F, patch=patch, normals=N)
        key = f"features-{patch}-{m.frame_index(frame)}"
        m.arrays[key] = mask.astype(np.uint8)
        return {
            "n_features": int(mask.sum()),
            "n_vertices": int(len(V)),
            "patch": patch,
            "frame": m.frame_index(frame),
            "method": method,
            "key": key,
        }

    def curves(self, m: Model, patch, frame, job: Job | None = None) -> dict:
        patch = _as_int(patch, "patch", 3)
        t = m.frame_index(frame)
        fkey = f"features-{patch}-{t}"
        if fkey not in m.arrays:
            if job:
                job.update(0.05, "feature vertices")
            self.features(m, patch, t)
        if job:
            job.update(0.4, "mean curvature and k-means (Calinski-Harabasz)")
        V, F, _ = m.geometry(t)
        lab = _analysis.feature_curves(V, F, m.arrays[fkey].astype(bool), patch=patch)
        key = f"curves-{patch}-{t}"
        m.arrays[key] = lab.astype(np.int8)
        return {"n_curves": int(lab.max() + 1) if lab.size else 0, "key": key, "patch": patch}

    def scalar(self, m: Model, name: str, frame, job: Job | None = None) -> dict:
        t = m.frame_index(frame)
        V, F, N = m.geometry(t)
        n = len(V)
        label = name
        if job:
            job.update(0.1, f"computing {name}")
        if name in ("saliency", "saliency-combined"):
            if F is None:
                raise InvalidInputError("saliency needs a mesh (faces).")
            method = "spectral" if name == "saliency" else "combined"
            vals = _analysis.saliency_field(V, F, method=method)
            label = f"saliency ({method}, Section 6.1.2)"
        elif name == "curvature":
            vals = _analysis.curvature(V, F)
            label = "mean curvature" if F is not None else "surface variation"
        elif name == "feature-class":
            from ..geometry.features import classify_vertices

            Nn = _analysis.point_normals(V, N) if F is None else None
            vals = classify_vertices(V, F, patch=15, normals=Nn).labels.astype(np.float64)
            label = "feature class (0 flat, 1 edge, 2 corner; patch 15)"
        elif name.startswith("attr:"):
            attrs = (m.obj.vertex_attributes if m.kind == "mesh" else m.obj.attributes) or {}
            if name[5:] not in attrs:
                raise InvalidInputError(f"unknown attribute {name[5:]!r}.")
            vals = _analysis.vertex_field(attrs[name[5:]], n, F)
        elif name.startswith("face:"):
            attrs = (m.obj.face_attributes if m.kind == "mesh" else None) or {}
            if name[5:] not in attrs:
                raise InvalidInputError(f"unknown face attribute {name[5:]!r}.")
            vals = _analysis.vertex_field(attrs[name[5:]], n, F)
            label = f"{name[5:]} (per face, mean over incident faces)"
        elif name.startswith("field:"):
            if name[6:] not in m.fields:
                raise InvalidInputError(f"unknown field {name[6:]!r}.")
            vals = _analysis.vertex_field(m.fields[name[6:]], n, F)
            label = name[6:]
        else:
            raise InvalidInputError(f"unknown scalar field {name!r}.")
        return self._heat(m, f"scalar-{name}-{t}", vals, label)

    def lod(self, m: Model, max_faces=100_000, max_points=150_000) -> dict:
        """Vertex-clustering proxy of frame 0 drawn while the camera moves (see ``_lod``).

        Its vertices are original vertices (``reps``), so the browser gathers positions of any frame
        and per-vertex colours at ``reps``; ``faces`` index into ``reps``. Cached per budget.
        """
        from ._lod import vertex_clustering

        max_faces = _as_int(max_faces, "max_faces", 1)
        max_points = _as_int(max_points, "max_points", 1)
        key = f"lod-{max_faces}-{max_points}"
        if key + "-reps" not in m.arrays:
            V, F, _ = m.geometry(0)
            p = vertex_clustering(V, F, max_faces=max_faces, max_points=max_points)
            faces = np.zeros((0, 3), np.uint32) if p.faces is None else p.faces.astype(np.uint32)
            m.arrays[key + "-faces"] = faces
            m.arrays[key + "-reps"] = p.reps.astype(np.uint32)
            m.arrays[key + "-meta"] = np.array([p.resolution, p.cell_size])
        meta = m.arrays[key + "-meta"]
        return {
            "reps": key + "-reps",
            "faces": key + "-faces",
            "n_vertices": int(len(m.arrays[key + "-reps"])),
            "n_faces": int(len(m.arrays[key + "-faces"])),
            "resolution": int(meta[0]),
            "cell_size": float(meta[1]),
        }

    def _heat(self, m: Model, key: str, vals, label: str) -> dict:
        from .._colormap import jet

        vals = np.asarray(vals, dtype=np.float64)
        fin = np.isfinite(vals)
        vmin = float(vals[fin].min()) if fin.any() else 0.0
        vmax = float(vals[fin].max()) if fin.any() else 1.0
        m.arrays[key + "-values"] = vals.astype(np.float32)
        m.arrays[key + "-colors"] = jet(vals, n_classes=64)
        return {
            "label": label,
            "vmin": vmin,
            "vmax": vmax,
            "values": key + "-values",
            "colors": key + "-colors",
            "colorbar": colorbar(),
        }

    def compare(self, a: Model, b: Model, frame, job: Job | None = None) -> dict:
        """Metrics of Section 4.9 of ``b`` (result) against ``a`` (reference)."""
        from .. import metrics

        Va, Fa, _ = a.geometry(a.frame_index(frame) if a.n_frames > 1 else 0)
        Vb, Fb, _ = b.geometry(b.frame_index(frame) if b.n_frames > 1 else 0)
        if Va.shape != Vb.shape:
            raise InvalidInputError(
                f"cannot compare {a.name} ({len(Va)} vertices) with {b.name} ({len(Vb)}): "
                "the metrics need the same vertices in the same order."
            )
        if job:
            job.update(0.2, "metrics (theta, distances, Hausdorff)")
        if Fa is not None:
            if Fb is not None and not np.array_equal(Fa, Fb):
                raise InvalidInputError(
                    f"{a.name} and {b.name} have different faces; the metrics need one connectivity."
                )
            table = metrics.compare(Vb, Va, Fa)
        else:
            d = np.linalg.norm(Vb - Va, axis=1)
            table = {"dmean": float(d.mean()), "dmax": float(d.max())}
        dist = np.linalg.norm(Vb - Va, axis=1)
        heat = self._heat(b, f"dist-{a.id}", dist, f"|v - v_ref| to {a.name}")
        return {"metrics": {k: float(v) for k, v in table.items()}, "heat": heat, "b": b.id}

    def denoise(self, m: Model, method: str, job: Job) -> dict:
        from .. import denoise
        from ..geometry import Mesh, MeshAnimation

        info = denoise.get(str(method))
        if m.kind == "mesh":
            job.update(0.05, f"{info.name} on {m.obj.n_vertices} vertices")
            V = denoise.denoise(m.obj.vertices, m.obj.faces, method=info.name)
            out = Mesh(np.asarray(V, dtype=np.float64), m.obj.faces)
        elif m.kind == "animation":
            frames = []
            for t in range(m.n_frames):
                job.update(t / m.n_frames, f"{info.name}: frame {t + 1}/{m.n_frames}")
                frames.append(denoise.denoise(m.obj.frames[t], m.obj.faces, method=info.name))
            out = MeshAnimation(np.stack(frames), m.obj.faces)
        else:
            raise InvalidInputError(f"denoising needs a mesh or a mesh animation; got {m.kind}.")
        new = self.add(out, f"{_stem(m.name)}-{info.name}{_ext(m)}", source=m.id)
        return {"model": new.info()}

    def outliers(self, m: Model, method: str, k, job: Job) -> dict:
        from .. import outliers
        from ..geometry import PointCloud

        k = _as_int(k, "k", 1)
        if m.kind not in ("points", "mesh"):
            raise InvalidInputError(
                f"outlier removal works on one point cloud (or a mesh's vertices); got {m.kind}."
            )
        P = m.obj.points if m.kind == "points" else m.obj.vertices
        pc = m.obj if m.kind == "points" else PointCloud(P)
        job.update(0.05, f"{method} outlier scores of {len(P)} points (k={k})")
        remove = getattr(outliers, "remove_outliers", None)
        if remove is not None:
            res = remove(pc, method=str(method), k=k)
            keep = np.asarray(res.keep, dtype=bool)
            scores = np.asarray(res.scores, dtype=np.float64)
        else:
            # Algorithm 14 with the RPCA scores; threshold: scores above mean + 3 std
            if method != "rpca":
                raise InvalidInputError(f"unknown outlier method {method!r}; available: rpca.")
            scores = np.asarray(outliers.rpca_scores(P, k).scores, dtype=np.float64)
            keep = scores < scores.mean() + 3 * scores.std()
        heat = self._heat(m, f"outlier-score-{method}-{k}", scores, f"outlier score ({method})")
        new = self.add(pc.select(keep), f"{_stem(m.name)}-clean.ply", source=m.id)
        return {"model": new.info(), "n_removed": int((~keep).sum()), "heat": heat}

    def fill_holes(self, m: Model, method: str, max_hole, job: Job, density=1.0) -> dict:
        """Close the holes of a mesh (:func:`spectrageo.complete.fill_holes`, as ``spectrageo
        complete IN OUT --fill-holes``); the result is a new model, the input rows first."""
        from .. import complete
        from ..geometry import Mesh, boundary_loops

        if m.kind != "mesh":
            raise InvalidInputError(f"hole filling needs a mesh; got {m.kind}.")
        # the library's checks, before the loops are searched
        check_choice(method, "method", complete.INPAINT_METHODS)
        check_positive(density, "density")
        mh = None if max_hole in (None, "", 0) else _as_int(max_hole, "max_hole", 3)
        V, F = m.obj.vertices, m.obj.faces
        loops = boundary_loops(F, V.shape[0])
        if not loops:
            raise InvalidInputError(f"{m.name} has no hole (no boundary edge); nothing to fill.")
        job.update(0.05, f"closing {len(loops)} boundary loop(s) ({method})")
        V2, F2 = complete.fill_holes(V, F, method=method, max_hole=mh, density=density)
        new = self.add(Mesh(V2, F2), f"{_stem(m.name)}-filled{_ext(m)}", source=m.id)
        return {
            "model": new.info(),
            "n_loops": len(loops),
            "n_implanted": int(V2.shape[0] - V.shape[0]),
            "n_faces_added": int(F2.shape[0] - F.shape[0]),
        }

    def download(self, m: Model, fmt: str) -> tuple[bytes, str]:
        """(file bytes, suggested name) of ``m`` written as ``fmt``."""
        from .. import io

        fmt = str(fmt)
        fmt = fmt if fmt.startswith(".") else "." + fmt
        allowed = io.supported_formats()["write"][m.kind]
        if fmt not in allowed:
            raise InvalidInputError(
                f"cannot write a {m.kind} as {fmt}; choose one of {', '.join(allowed)}."
            )
        name = _stem(m.name).split(".")[0] + fmt
        folder, own = self._scratch()
        p = folder / f"download-{uuid.uuid4().hex}{fmt}"
        try:
            io.write(p, m.obj)
            return p.read_bytes(), name
        finally:
            p.unlink(missing_ok=True)
            if own:
                shutil.rmtree(folder, ignore_errors=True)

    def attach_field(self, m: Model, data: bytes, name: str) -> str:
        """Attach a scalar field file (.npy, or text with one value per line / comma-separated)."""
        folder, own = self._scratch()
        p = folder / f"field-{uuid.uuid4().hex}"
        try:
            p.write_bytes(data)
            return self.attach_field_file(m, p, name)
        finally:
            p.unlink(missing_ok=True)
            if own:
                shutil.rmtree(folder, ignore_errors=True)

    def attach_field_file(self, m: Model, path: str | os.PathLike, name: str) -> str:
        """Attach the scalar field saved at ``path`` (``name`` is the user's name of the file).

        Memory stays proportional to the model: a ``.npy`` file is memory-mapped and its size
        checked before it is converted, a text file may hold at most 64 bytes per value.
        """
        stem = clean_name(name, default="field")
        path = Path(path)
        V, F, _ = m.geometry(0)
        sizes = (len(V),) if F is None else (len(V), len(F))
        try:
            if stem.lower().endswith(".npy"):
                mm = np.load(path, mmap_mode="r", allow_pickle=False)
                if mm.size not in sizes:
                    nf = "" if F is None else f" or faces ({len(F)})"
                    raise InvalidInputError(
                        f"scalar field has {mm.size} values; expected one per vertex "
                        f"({len(V)}){nf}."
                    )
                vals = np.array(mm, dtype=np.float64).ravel()
                del mm
            else:
                size = path.stat().st_size
                if size > 64 * (max(sizes) + 16):
                    raise InvalidInputError(
                        f"scalar file {stem} is too large ({size} bytes) for {len(V)} vertices."
                    )
                txt = path.read_bytes().decode("utf-8").replace(",", " ").replace(";", " ")
                vals = np.array(txt.split(), dtype=np.float64)
            vals = np.asarray(vals, dtype=np.float64).ravel()
        except InvalidInputError:
            raise
        except Exception as exc:  # noqa: BLE001 - bad user file
            raise InvalidInputError(f"could not read scalar file {stem}: {exc}") from exc
        _analysis.vertex_field(vals, len(V), F)  # validates the length
        m.fields[stem] = vals
        self.trim()
        return f"field:{stem}"


def colorbar() -> list[list[int]]:
    """The 64 jet classes, low to high, as RGB triples."""
    from .._colormap import jet

    return jet(np.arange(64), n_classes=64, vmin=0, vmax=63).tolist()


def _ext(m: Model) -> str:
    return ".npz" if m.kind in ("animation", "sequence") else ".ply"


def _as_int(value, name: str, minimum: int) -> int:
    try:
        if isinstance(value, bool):
            raise TypeError
        v = int(value)
        if v != float(value):
            raise ValueError
    except (TypeError, ValueError, OverflowError):
        raise InvalidInputError(f"`{name}` must be an integer; got {value!r}.") from None
    if v < minimum:
        raise InvalidInputError(f"`{name}` must be >= {minimum}; got {v}.")
    return v


# --------------------------------------------------------------------------- HTTP
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
        left = n
        while left > 0:
            c = self.rfile.read(min(left, CHUNK))
            if not c:
                raise ConnectionError("the client closed the connection during the upload")
            out.write(c)
            left -= len(c)
            self._unread = left

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
    def do_GET(self):  # noqa: N802
        self._dispatch("GET")

    def do_HEAD(self):  # noqa: N802
        self._dispatch("GET")

    def do_POST(self):  # noqa: N802
        self._dispatch("POST")

    def do_OPTIONS(self):  # noqa: N802 - CORS preflights are never approved
        self._dispatch("OPTIONS")

    def do_PUT(self):  # noqa: N802
        self._dispatch("PUT")

    def do_DELETE(self):  # noqa: N802
        self._dispatch("DELETE")

    def do_PATCH(self):  # noqa: N802
        self._dispatch("PATCH")

    def _parts(self) -> list[str]:
        return [unquote(p) for p in urlsplit(self.path).path.split("/") if p]

    def _dispatch(self, method: str) -> None:
        url = urlsplit(self.path)
        q = {k: v[-1] for k, v in parse_qs(url.query).items()}
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
                self._json({"error": f"not found: {url.path}"}, 404)
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
        """Host for everything; same origin and the session token for the API."""
        if not self._host_ok():
            raise _Refused(403, "forbidden host")
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

    def _host_ok(self) -> bool:
        host = (self.headers.get("Host") or "").rsplit(":", 1)[0].strip("[]")
        return host in ("127.0.0.1", "localhost", "::1", "")

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
    """Threaded server with a connection cap and a deadline for receiving request headers."""

    daemon_threads = True
    block_on_close = False

    def __init__(self, address, handler, *, max_connections: int):
        super().__init__(address, handler)
        self.max_connections = max_connections
        self._active = 0
        self._lock = threading.Lock()
        self._deadlines: dict[socket.socket, float] = {}
        self._closed = threading.Event()
        self._reaper = threading.Thread(target=self._reap, daemon=True, name="spectrageo-reaper")
        self._reaper.start()

    @property
    def active_connections(self) -> int:
        return self._active

    def process_request(self, request, client_address):
        with self._lock:
            full = self._active >= self.max_connections
            if not full:
                self._active += 1
        if full:
            self._refuse(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            with self._lock:
                self._active -= 1
            raise

    def process_request_thread(self, request, client_address):
        try:
            super().process_request_thread(request, client_address)
        finally:
            with self._lock:
                self._active -= 1
                self._deadlines.pop(request, None)

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
            self._deadlines[sock] = time.monotonic() + seconds

    def unwatch(self, sock) -> None:
        with self._lock:
            self._deadlines.pop(sock, None)

    def _reap(self) -> None:
        while not self._closed.wait(0.2):
            now = time.monotonic()
            with self._lock:
                late = [s for s, t in self._deadlines.items() if t < now]
                for s in late:
                    del self._deadlines[s]
            for s in late:
                try:
                    s.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass

    def server_close(self):
        self._closed.set()
        super().server_close()


class ViewerServer:
    """The viewer's HTTP server on ``127.0.0.1``.

    Parameters
    ----------
    paths : list of path-like
        Files (or frame folders) to load at start.
    port : int
        TCP port; 0 picks a free one.
    verbose : bool
        Log every request on stderr.
    limits : ViewerLimits, optional
        Resource limits; by default :meth:`ViewerLimits.from_env` with ``**overrides``
        (``max_upload_mb=``, ``max_models=``, ``max_memory_mb=``, ``max_jobs=``, ``max_queued=``,
        ``max_uploads=``, ``request_timeout=``, ``max_connections=``).

    Attributes
    ----------
    token : str
        The per-session token; API clients send it in the ``X-Spectrageo-Token`` header
        (:attr:`api_headers`).
    tmp_dir : Path
        Private temporary folder (``spectrageo-view-<PID>-*``), removed by :meth:`stop`, at
        interpreter exit, and by the next viewer started after a crash.

    Examples
    --------
    >>> srv = ViewerServer(["fandisk.off"], port=0).start()   # doctest: +SKIP
    >>> srv.url                                                # doctest: +SKIP
    'http://127.0.0.1:40123/'
    >>> srv.stop()                                             # doctest: +SKIP
    """

    def __init__(
        self,
        paths=(),
        *,
        port: int = 0,
        verbose: bool = False,
        limits: ViewerLimits | None = None,
        **overrides,
    ):
        self.limits = ViewerLimits.from_env(**overrides) if limits is None else limits
        if limits is not None and overrides:
            self.limits = replace(limits, **overrides)
        self.removed_stale = remove_stale_temp_dirs()
        self.tmp_dir = _make_temp_dir()
        self._atexit = functools.partial(shutil.rmtree, self.tmp_dir, ignore_errors=True)
        atexit.register(self._atexit)
        self._serving = False
        self._closed = False
        self.httpd = None
        try:
            self.session = ViewerSession(self.limits, tmp_dir=self.tmp_dir)
            for p in paths:
                self.session.load_path(p)
            self.token = secrets.token_urlsafe(32)
            handler = type(
                "Handler",
                (_Handler,),
                {
                    "session": self.session,
                    "quiet": not verbose,
                    "token": self.token,
                    "limits": self.limits,
                    "timeout": float(self.limits.request_timeout),
                    "tmp_dir": self.tmp_dir,
                    "upload_slots": threading.BoundedSemaphore(self.limits.max_uploads),
                },
            )
            self.httpd = _HTTPServer(
                ("127.0.0.1", int(port)), handler, max_connections=self.limits.max_connections
            )
        except BaseException:
            self.stop()
            raise
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        return int(self.httpd.server_address[1])

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    @property
    def api_headers(self) -> dict[str, str]:
        """Headers an API client (a script, a test) needs: the session token."""
        return {TOKEN_HEADER: self.token}

    def start(self) -> ViewerServer:
        """Serve in a background thread (returns self)."""
        self._serving = True
        self._thread = threading.Thread(target=self._serve, daemon=True, name="spectrageo-view")
        self._thread.start()
        return self

    def _serve(self) -> None:
        self._serving = True
        try:
            self.httpd.serve_forever()
        finally:
            self._serving = False

    def serve_forever(self) -> None:
        self._serve()

    def stop(self) -> None:
        """Stop serving, close the socket, stop the job workers and remove the temporary folder."""
        if self._closed:
            return
        self._closed = True
        if self.httpd is not None:
            # shutdown() waits for serve_forever() to return; when it ran in this thread (the CLI,
            # interrupted by Ctrl+C or SIGTERM) it has already stopped -- possibly before it
            # entered its loop, when the wait would never end -- so only a server thread is asked
            if self._serving and self._thread is not None and self._thread.is_alive():
                if self._thread is not threading.current_thread():
                    self.httpd.shutdown()
            self.httpd.server_close()
        session = getattr(self, "session", None)
        if session is not None:
            session.close()
        shutil.rmtree(self.tmp_dir, ignore_errors=True)
        atexit.unregister(self._atexit)

    close = stop

    def __enter__(self) -> ViewerServer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


__all__ = [
    "Job",
    "Model",
    "ViewerBusyError",
    "ViewerLimits",
    "ViewerServer",
    "ViewerSession",
    "clean_name",
    "colorbar",
    "content_disposition",
    "remove_stale_temp_dirs",
]
