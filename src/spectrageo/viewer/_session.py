"""The viewer's state: loaded models, their arrays, and the library calls behind the API."""

from __future__ import annotations

import itertools
import os
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError, SpectrageoError
from .._validation import check_choice, check_positive
from . import _analysis
from ._files import _stem, clean_name, file_suffix, scratch_file
from ._jobs import Job, ViewerBusyError, _error_text, _JobPool
from ._limits import ViewerLimits, _check_expansion

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

    def close(self, timeout: float = 0.0) -> bool:
        """Cancel the jobs (queued ones end at once, running ones at their next progress update)
        and wait up to ``timeout`` seconds for the workers; whether they all ended."""
        with self._lock:
            jobs = list(self.jobs.values())
        for j in jobs:
            j.cancel()
        return self._pool.close(timeout)

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

    def load_path(self, path: str | os.PathLike, name: str | None = None) -> Model:
        from .. import io

        p = Path(path)
        obj = io.read(p)
        return self.add(obj, name or p.name, source=str(p))

    def load_file(self, path: str | os.PathLike, name: str) -> Model:
        """Read an uploaded file saved at ``path``; ``name`` is the user's name of it."""
        from .. import io
        from ..io._common import lowered_cap

        name = clean_name(name)
        _check_expansion(Path(path), name, self.limits)
        advice = f"a quarter of the viewer's --max-memory of {self.limits.max_memory_mb:g} MB"
        try:
            with lowered_cap(self.limits.max_read_bytes, advice):
                obj = io.read(Path(path))
        except Exception as exc:  # noqa: BLE001 - any reader failure is a bad upload
            text = str(exc) if isinstance(exc, SpectrageoError) else f"{type(exc).__name__}: {exc}"
            text = text.replace(str(path), name).replace(Path(path).name, name)
            raise InvalidInputError(f"could not read {name}: {text}") from exc
        return self.add(obj, name, source="upload")

    def load_bytes(self, data: bytes, name: str) -> Model:
        """Read an uploaded file; the name (its extension) selects the reader."""
        with scratch_file(self.tmp_dir, "upload", file_suffix(clean_name(name))) as p:
            p.write_bytes(data)
            return self.load_file(p, name)

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
        """Run ``fn(job) -> result`` on the pool, ``models`` pinned (ViewerBusyError when full)."""
        job = Job(desc)
        models = tuple(models)

        def run():
            job.queued = False
            job.message = desc
            try:
                job.update()  # a job cancelled while queued ends here
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
        """Array keys of frame 0's vertex-clustering proxy (``_lod``: ``reps``, ``faces``)."""
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
        """Close a mesh's holes (:func:`spectrageo.complete.fill_holes`) into a new model."""
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
        with scratch_file(self.tmp_dir, "download", fmt) as p:
            io.write(p, m.obj)
            return p.read_bytes(), name

    def attach_field(self, m: Model, data: bytes, name: str) -> str:
        """Attach a scalar field file (.npy, or text with one value per line / comma-separated)."""
        with scratch_file(self.tmp_dir, "field") as p:
            p.write_bytes(data)
            return self.attach_field_file(m, p, name)

    def attach_field_file(self, m: Model, path: str | os.PathLike, name: str) -> str:
        """Attach the scalar field saved at ``path`` (``name``: the user's name of the file). A
        ``.npy`` is size-checked memory-mapped; a text file may hold 64 bytes per value."""
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
