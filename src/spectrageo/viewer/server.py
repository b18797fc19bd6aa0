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
``POST /api/compare``                     ``{"a": ID, "b": ID, "frame": 0}`` -> job (metrics table)
``GET  /api/job/JOB``                     ``{"state", "progress", "message", "elapsed", "result"|"error"}``
========================================  =====================================================
"""

from __future__ import annotations

import json
import mimetypes
import os
import re
import shutil
import tempfile
import threading
import time
import traceback
import uuid
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, unquote, urlsplit

import numpy as np

from .._errors import InvalidInputError, SpectrageoError
from . import _analysis

STATIC_DIR = Path(__file__).resolve().parent / "static"
MAX_UPLOAD = 4 << 30
_SAFE_NAME = re.compile(r"[^A-Za-z0-9._+-]+")


# --------------------------------------------------------------------------- models
@dataclass
class Model:
    """One loaded geometry and the arrays computed for it."""

    id: str
    name: str
    obj: Any
    source: str = ""
    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    fields: dict[str, np.ndarray] = field(default_factory=dict)  # user scalar fields

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
    """A background computation with progress, polled by the browser."""

    def __init__(self, desc: str):
        self.id = uuid.uuid4().hex[:12]
        self.desc = desc
        self.state = "running"
        self.progress: float | None = None
        self.message = desc
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
            "progress": self.progress,
            "message": self.message,
            "elapsed": round(end - self.started, 3),
        }
        if self.result is not None:
            d["result"] = self.result
        if self.error is not None:
            d["error"] = self.error
        return d


def _error_text(exc: BaseException) -> str:
    if isinstance(exc, (SpectrageoError, ValueError)):
        return str(exc)
    return f"internal error: {type(exc).__name__}: {exc}"


# --------------------------------------------------------------------------- session
class ViewerSession:
    """The models and jobs of one viewer server (thread-safe)."""

    def __init__(self):
        self._lock = threading.Lock()
        self.models: dict[str, Model] = {}
        self.jobs: dict[str, Job] = {}
        self._counter = 0

    # ---- models
    def add(self, obj, name: str, source: str = "") -> Model:
        with self._lock:
            self._counter += 1
            mid = f"m{self._counter}"
            m = Model(mid, name, obj, source)
            self.models[mid] = m
        return m

    def load_path(self, path: str | os.PathLike, name: str | None = None) -> Model:
        from .. import io

        p = Path(path)
        obj = io.read(p)
        return self.add(obj, name or p.name, source=str(p))

    def load_bytes(self, data: bytes, name: str) -> Model:
        """Read an uploaded file; the name (its extension) selects the reader."""
        from .. import io

        safe = _SAFE_NAME.sub("_", Path(name or "upload").name).strip("._") or "upload"
        tmp = Path(tempfile.mkdtemp(prefix="spectrageo-view-"))
        try:
            p = tmp / safe
            p.write_bytes(data)
            try:
                obj = io.read(p)
            except SpectrageoError as exc:
                raise InvalidInputError(f"could not read {name}: {exc}") from exc
            except Exception as exc:  # noqa: BLE001 - any reader failure is a bad upload
                raise InvalidInputError(
                    f"could not read {name}: {type(exc).__name__}: {exc}"
                ) from exc
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return self.add(obj, Path(name).name, source="upload")

    def get(self, mid: str) -> Model:
        m = self.models.get(mid)
        if m is None:
            raise InvalidInputError(f"unknown model {mid!r}.")
        return m

    # ---- jobs
    def start(self, desc: str, fn) -> Job:
        """Run ``fn(job) -> dict`` in a thread; its dict becomes the job's result."""
        job = Job(desc)
        with self._lock:
            self.jobs[job.id] = job

        def run():
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

        threading.Thread(target=run, daemon=True, name=f"spectrageo-job-{job.id}").start()
        return job

    def job(self, jid: str) -> Job:
        j = self.jobs.get(jid)
        if j is None:
            raise InvalidInputError(f"unknown job {jid!r}.")
        return j

    # ---- computations (each returns a JSON-able dict; arrays are stored on the model)
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
        new = self.add(out, f"{Path(m.name).stem}-{info.name}{_ext(m)}", source=m.id)
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
        new = self.add(pc.select(keep), f"{Path(m.name).stem}-clean.ply", source=m.id)
        return {"model": new.info(), "n_removed": int((~keep).sum()), "heat": heat}

    def download(self, m: Model, fmt: str) -> tuple[bytes, str]:
        from .. import io

        fmt = fmt if fmt.startswith(".") else "." + fmt
        allowed = io.supported_formats()["write"][m.kind]
        if fmt not in allowed:
            raise InvalidInputError(
                f"cannot write a {m.kind} as {fmt}; choose one of {', '.join(allowed)}."
            )
        name = Path(m.name).name.split(".")[0] + fmt
        tmp = Path(tempfile.mkdtemp(prefix="spectrageo-view-"))
        try:
            io.write(tmp / name, m.obj)
            return (tmp / name).read_bytes(), name
        finally:
            shutil.rmtree(tmp, ignore_errors=True)

    def attach_field(self, m: Model, data: bytes, name: str) -> str:
        """Attach a scalar field file (.npy, or text with one value per line / comma-separated)."""
        import io as _io

        stem = Path(name).name
        try:
            if stem.lower().endswith(".npy"):
                vals = np.load(_io.BytesIO(data), allow_pickle=False)
            else:
                txt = data.decode("utf-8").replace(",", " ").replace(";", " ")
                vals = np.array(txt.split(), dtype=np.float64)
            vals = np.asarray(vals, dtype=np.float64).ravel()
        except Exception as exc:  # noqa: BLE001 - bad user file
            raise InvalidInputError(f"could not read scalar file {stem}: {exc}") from exc
        V, F, _ = m.geometry(0)
        _analysis.vertex_field(vals, len(V), F)  # validates the length
        m.fields[stem] = vals
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
    except (TypeError, ValueError):
        raise InvalidInputError(f"`{name}` must be an integer; got {value!r}.") from None
    if v < minimum:
        raise InvalidInputError(f"`{name}` must be >= {minimum}; got {v}.")
    return v


# --------------------------------------------------------------------------- HTTP
class _Handler(BaseHTTPRequestHandler):
    server_version = "spectrageo-view"
    protocol_version = "HTTP/1.1"
    session: ViewerSession  # set on the subclass made by ViewerServer
    quiet = True

    def log_message(self, fmt, *args):  # noqa: D401 - silence the default stderr log
        if not self.quiet:
            super().log_message(fmt, *args)

    # ---- replies
    def _send(self, status: int, body: bytes, ctype: str, headers: dict | None = None) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        for k, v in (headers or {}).items():
            self.send_header(k, v)
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, obj, status: int = 200) -> None:
        self._send(status, json.dumps(obj).encode(), "application/json")

    def _array(self, a: np.ndarray) -> None:
        a = np.ascontiguousarray(a)
        dt = a.dtype.newbyteorder("<") if a.dtype.byteorder == ">" else a.dtype
        self._send(
            200,
            a.astype(dt, copy=False).tobytes(),
            "application/octet-stream",
            {"X-Dtype": dt.name, "X-Shape": ",".join(map(str, a.shape))},
        )

    def _body(self) -> bytes:
        n = self.headers.get("Content-Length")
        if n is None:
            raise InvalidInputError("the request needs a Content-Length header.")
        n = int(n)
        if n > MAX_UPLOAD:
            raise InvalidInputError(f"upload too large ({n} bytes; limit {MAX_UPLOAD}).")
        chunks, left = [], n
        while left > 0:
            c = self.rfile.read(min(left, 1 << 20))
            if not c:
                break
            chunks.append(c)
            left -= len(c)
        return b"".join(chunks)

    def _params(self) -> dict:
        data = self._body()
        if not data:
            return {}
        try:
            obj = json.loads(data)
        except json.JSONDecodeError as exc:
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

    def _dispatch(self, method: str) -> None:
        url = urlsplit(self.path)
        q = {k: v[-1] for k, v in parse_qs(url.query).items()}
        parts = [unquote(p) for p in url.path.split("/") if p]
        try:
            if not self._host_ok():
                self._json({"error": "forbidden host"}, 403)
                return
            if method == "GET" and parts == ["favicon.ico"]:
                self._send(204, b"", "image/x-icon")
            elif method == "GET" and (not parts or parts[0] == "static"):
                self._static(parts[1:] if parts else ["index.html"])
            elif parts and parts[0] == "api":
                self._api(method, parts[1:], q)
            else:
                self._json({"error": f"not found: {url.path}"}, 404)
        except (SpectrageoError, ValueError) as exc:
            self._json({"error": str(exc)}, 400)
        except (BrokenPipeError, ConnectionResetError):
            pass
        except Exception as exc:  # noqa: BLE001 - the server must stay up
            if os.environ.get("SPECTRAGEO_DEBUG"):
                traceback.print_exc()
            self._json({"error": _error_text(exc)}, 500)

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
        self._send(200, p.read_bytes(), ctype)

    def _api(self, method: str, parts: list[str], q: dict) -> None:
        s = self.session
        route = (method, parts[0] if parts else "")
        if route == ("GET", "state"):
            self._json(_state(s))
        elif route == ("POST", "upload"):
            m = s.load_bytes(self._body(), q.get("name", "upload"))
            self._json({"model": m.info()})
        elif route == ("POST", "field-upload"):
            m = s.get(q.get("model", ""))
            fname = s.attach_field(m, self._body(), q.get("name", "field.txt"))
            self._json({"field": fname, "model": m.info()})
        elif route == ("GET", "job") and len(parts) == 2:
            self._json(s.job(parts[1]).to_json())
        elif route == ("POST", "compare"):
            p = self._params()
            a, b = s.get(str(p.get("a"))), s.get(str(p.get("b")))
            job = s.start("compare", lambda j: s.compare(a, b, p.get("frame", 0), j))
            self._json({"job": job.id})
        elif parts and parts[0] == "model" and len(parts) >= 2:
            self._model(method, s.get(parts[1]), parts[2:], q)
        else:
            self._json({"error": f"no such API: {method} /api/{'/'.join(parts)}"}, 404)

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
                    {"Content-Disposition": f'attachment; filename="{name}"'},
                )
            else:
                self._json({"error": f"no such API: GET model/{what}"}, 404)
            return
        p = self._params()
        frame = p.get("frame", 0)
        if what == "features":
            job = s.start("features", lambda j: s.features(m, p.get("patch", 15), frame, j))
        elif what == "curves":
            job = s.start("feature curves", lambda j: s.curves(m, p.get("patch", 15), frame, j))
        elif what == "scalar":
            job = s.start("heatmap", lambda j: s.scalar(m, str(p.get("field", "")), frame, j))
        elif what == "denoise":
            job = s.start("denoising", lambda j: s.denoise(m, p.get("method", "tsgsp"), j))
        elif what == "outliers":
            job = s.start(
                "outlier removal",
                lambda j: s.outliers(m, p.get("method", "rpca"), p.get("k", 10), j),
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
        "formats": io.supported_formats(),
        "feature_method": _analysis.SALIENCY_SOURCE
        if _analysis._saliency_fn("feature_vertices")
        else _analysis.FEATURE_SOURCE,
    }


def _outlier_methods() -> list[str]:
    from .. import outliers

    names = getattr(outliers, "METHODS", None)
    if names:
        return list(names)
    return ["rpca"]


class ViewerServer:
    """The viewer's HTTP server on ``127.0.0.1``.

    Parameters
    ----------
    paths : list of path-like
        Files (or frame folders) to load at start.
    port : int
        TCP port; 0 picks a free one.

    Examples
    --------
    >>> srv = ViewerServer(["fandisk.off"], port=0).start()   # doctest: +SKIP
    >>> srv.url                                                # doctest: +SKIP
    'http://127.0.0.1:40123/'
    >>> srv.stop()                                             # doctest: +SKIP
    """

    def __init__(self, paths=(), *, port: int = 0, verbose: bool = False):
        self.session = ViewerSession()
        for p in paths:
            self.session.load_path(p)
        handler = type("Handler", (_Handler,), {"session": self.session, "quiet": not verbose})
        self.httpd = ThreadingHTTPServer(("127.0.0.1", int(port)), handler)
        self.httpd.daemon_threads = True
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        return int(self.httpd.server_address[1])

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    def start(self) -> ViewerServer:
        """Serve in a background thread (returns self)."""
        self._thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self._thread.start()
        return self

    def serve_forever(self) -> None:
        self.httpd.serve_forever()

    def stop(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


__all__ = ["Job", "Model", "ViewerServer", "ViewerSession", "colorbar"]
