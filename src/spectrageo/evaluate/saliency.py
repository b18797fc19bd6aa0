"""``spectrageo evaluate saliency``: saliency maps against the reference maps of ``saliency/``.

For every model (block, cad, casting, fandisk) and every method it reports:

* Pearson and Spearman correlation of the per-face map with the per-face reference map
  (``<model>_saliencyValues_of_centroids.csv``);
* the run time (including guided normals and patches), wall clock and CPU time of the process (all
  threads; steadier than wall time on a shared machine), and for ``fast`` the speed-up over
  ``combined`` in both and the Pearson correlation of the two maps (Table 6.1);
* stability (Figs. 6.16-6.17, Pearson of per-vertex maps): a rotated + uniformly scaled +
  translated copy (``invariance``), a copy with 30 % of the vertices removed (saliency-agnostic
  decimation, compared at the remaining vertices), and a copy with Gaussian noise along the normals
  of 0.1 of the mean edge length.

Methods: ``combined``, ``fast`` (combined with the fast variant), ``spectral``, ``geometric``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.stats import pearsonr, spearmanr

from .._errors import InvalidInputError
from .._progress import progress
from ..datasets.splits import cases as _cases
from ..datasets.splits import split_of
from ._tables import rows_to_csv, write_md_csv

#: the reference-map models of the split registry's ``saliency`` task
#: (:mod:`spectrageo.datasets.splits`; they chose ``sparse_norm``, so they are not held out for it)
MODELS = tuple(c.name for c in _cases("saliency"))
METHODS = ("combined", "fast", "spectral", "geometric")
COLUMNS = (
    "model",
    "method",
    "n_faces",
    "pearson",
    "spearman",
    "time_s",
    "cpu_s",
    "speedup_pct",
    "cpu_speedup_pct",
    "pearson_vs_combined",
    "invariance",
    "decimation",
    "noise",
    "split",
)


def _rotation(rng) -> np.ndarray:
    Q, R = np.linalg.qr(rng.standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def _opts(method: str) -> dict:
    if method == "fast":
        from ..saliency import SaliencyOptions

        return {"method": "combined", "options": SaliencyOptions(fast=True)}
    return {"method": method}


def _pearson(a, b) -> float:
    if np.ptp(a) == 0 or np.ptp(b) == 0:
        return float("nan")
    return float(pearsonr(a, b)[0])


def evaluate(
    data_dir,
    methods=None,
    out=None,
    *,
    models=MODELS,
    stability: bool = True,
    seed: int = 0,
    repeat: int = 1,
) -> list[dict]:
    """Run the saliency evaluation; returns one row (dict over :data:`COLUMNS`) per model and method.

    Parameters
    ----------
    data_dir : path
        The shared data folder (containing ``saliency/``) or the ``saliency`` folder itself.
    methods : list of str, optional
        Subset of :data:`METHODS` (default all).
    out : path, optional
        Write ``<out>.md`` and ``<out>.csv`` atomically.
    models : sequence of str
        Model names (files ``<name>.obj`` and ``<name>_saliencyValues_of_centroids.csv``).
    stability : bool
        Also measure invariance, decimation and noise stability (three more maps per row).
    seed : int
        Seed of the random rotation, decimation and noise.
    repeat : int
        Runs per timing; the fastest is reported (wall-clock times on a shared machine vary).
    """
    from .. import io
    from ..noise import apply as add_noise
    from ..saliency import saliency, simplify

    root = Path(data_dir)
    folder = root / "saliency" if (root / "saliency").is_dir() else root
    if not folder.is_dir():
        raise InvalidInputError(f"`data_dir` must be a folder; got {data_dir}.")
    methods = list(METHODS) if methods is None else list(methods)
    for m in methods:
        if m not in METHODS:
            raise InvalidInputError(f"`methods` must be among {', '.join(METHODS)}; got {m!r}.")
    rows: list[dict] = []
    for name in progress(models, desc="saliency models", total=len(models)):
        mesh_path = folder / f"{name}.obj"
        gt_path = folder / f"{name}_saliencyValues_of_centroids.csv"
        if not mesh_path.is_file() or not gt_path.is_file():
            raise InvalidInputError(f"missing {mesh_path.name} or {gt_path.name} in {folder}.")
        mesh = io.read_mesh(mesh_path)
        V, F = mesh.vertices, mesh.faces
        gt = np.loadtxt(gt_path, dtype=np.float64).ravel()
        if gt.shape[0] != F.shape[0]:
            raise InvalidInputError(
                f"{gt_path.name} has {gt.shape[0]} values for {F.shape[0]} faces."
            )
        rng = np.random.default_rng(seed)
        R = _rotation(rng)
        V_rst = 3.7 * V @ R.T + rng.normal(scale=10.0, size=3)
        dec = simplify(V, F, ratio=0.3, saliency=np.zeros(len(V)), n_classes=1, rng=seed)
        V_noise = add_noise(V, F, kind="gaussian", level=0.1, rng=seed)
        base_face = base_time = base_cpu = None
        for method in methods:
            opts = _opts(method)
            dt = ct = np.inf
            for _ in range(max(1, int(repeat))):
                t0, c0 = time.perf_counter(), time.process_time()
                s_face = saliency(V, F, per="face", **opts)
                dt = min(dt, time.perf_counter() - t0)
                ct = min(ct, time.process_time() - c0)
            row = {
                "model": name,
                "method": method,
                "n_faces": int(F.shape[0]),
                "pearson": _pearson(s_face, gt),
                "spearman": float(spearmanr(s_face, gt)[0]),
                "time_s": dt,
                "cpu_s": ct,
                "speedup_pct": float("nan"),
                "cpu_speedup_pct": float("nan"),
                "pearson_vs_combined": float("nan"),
                "invariance": float("nan"),
                "decimation": float("nan"),
                "noise": float("nan"),
                "split": split_of("saliency", name) or "-",
            }
            if method == "combined":
                base_face, base_time, base_cpu = s_face, dt, ct
            if method == "fast" and base_face is not None:
                row["speedup_pct"] = 100.0 * (1.0 - dt / base_time)
                row["cpu_speedup_pct"] = 100.0 * (1.0 - ct / base_cpu)
                row["pearson_vs_combined"] = _pearson(s_face, base_face)
            if stability:
                from ..saliency._common import face_to_vertex

                s_v = face_to_vertex(s_face, F, len(V))
                row["invariance"] = _pearson(s_v, saliency(V_rst, F, **opts))
                row["decimation"] = _pearson(
                    s_v[dec.kept], saliency(dec.vertices, dec.faces, **opts)
                )
                row["noise"] = _pearson(s_v, saliency(V_noise, F, **opts))
            rows.append(row)
    if out is not None:
        write_tables(rows, out)
    return rows


def _fmt(key: str, v) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, int | np.integer):
        return f"{int(v):,}"
    if v is None or (isinstance(v, float) and np.isnan(v)):
        return "-"
    if key in ("time_s", "cpu_s"):
        return f"{v:.2f}"
    if key in ("speedup_pct", "cpu_speedup_pct"):
        return f"{v:.1f} %"
    return f"{v:.3f}"


def format_markdown(rows: list[dict]) -> str:
    """Markdown table of :func:`evaluate` rows."""
    head = (
        "| model | method | faces | Pearson | Spearman | wall (s) | CPU (s) | wall speed-up | "
        "CPU speed-up | Pearson vs combined | rot+scale+transl | 30 % decimated | noise 0.1 | "
        "split |"
    )
    lines = [head, "|" + "---|" * len(COLUMNS)]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(c, r.get(c)) for c in COLUMNS) + " |")
    return "\n".join(lines)


def format_csv(rows: list[dict]) -> str:
    """CSV text of the rows (full precision)."""
    return rows_to_csv(rows, COLUMNS)


def write_tables(rows: list[dict], out) -> tuple[Path, Path]:
    """Write ``<out>.md`` and ``<out>.csv`` atomically; returns both paths."""
    return write_md_csv(out, format_markdown(rows) + "\n", format_csv(rows))


__all__ = [
    "COLUMNS",
    "METHODS",
    "MODELS",
    "evaluate",
    "format_csv",
    "format_markdown",
    "write_tables",
]
