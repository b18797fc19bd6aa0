"""Outlier-removal evaluation on the shared real scans and animations (thesis Section 5.4).

Static clouds: labelled synthetic outliers (:func:`spectrageo.noise.add_outliers`) are injected
into real scans -- ``far`` (uniform in the enlarged bounding box) and ``near`` (a random scan point
displaced along its PCA normal by 1-3 mean point spacings) at 5/10/20 % of the scan size -- and
every method is scored by precision, recall and F1 of the removed points (positives = injected
outliers; the scans' own artefacts count as inliers) and by its wall time. ``sor-grid`` is the best
F1 of the statistical filter over ``k in {10, 20, 30}`` x ``std_ratio in {0.5, ..., 3}`` chosen
with the labels (an oracle for the baseline); ``rpca-oracle`` is likewise the RPCA scores cut at the
threshold of best F1 chosen with the labels (an upper bound for the automatic threshold of
``rpca``, same scores and time). ``open3d-sor`` runs when ``open3d`` imports.

Sequences: an animation's vertices as a point sequence, with 10-30 % of the points of every frame
displaced by 1-5 % of the bounding-box diagonal in random directions; per-frame theta (degrees,
face normals against the clean frame) and mean point-to-surface distance after consolidation
(Figs. 5.125-5.128), for :func:`spectrageo.outliers.clean_sequence` and for the RPCA low-rank
reconstruction (the thesis' comparison).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._progress import progress
from ._tables import rows_to_csv, write_md_csv

__all__ = ["DEFAULT_METHODS", "SCANS", "evaluate_outliers", "format_markdown"]

#: (label, path relative to the data folder) of the evaluated scans.
SCANS = (
    ("bunny bun000", "scans/bunny/bun000.ply.gz"),
    ("bunny top2", "scans/bunny/top2.ply.gz"),
    ("lidar autzen", "scans/lidar/autzen_trim.laz"),
    ("kinect milk", "scans/pcl/milk.pcd"),
    ("kinect table_scene_mug", "scans/pcl/table_scene_mug_stereo_textured.pcd"),
    ("fragment cloud_bin_0", "scans/registration/open3d/cloud_bin_0.pcd"),
    ("fragment cloud_bin_1", "scans/registration/open3d/cloud_bin_1.pcd"),
)
SEQUENCES = (("horse-gallop", "animations/horse-gallop.npz"),)
DEFAULT_METHODS = ("rpca", "sor", "sor-grid", "radius", "open3d-sor", "sequence")
_SOR_GRID = ((10, 20, 30), (0.5, 1.0, 1.5, 2.0, 2.5, 3.0))


def _prf(removed: np.ndarray, labels: np.ndarray) -> tuple[float, float, float]:
    tp = int(np.count_nonzero(removed & labels))
    p = tp / max(int(np.count_nonzero(removed)), 1)
    r = tp / max(int(np.count_nonzero(labels)), 1)
    return p, r, (2 * p * r / (p + r) if p + r > 0 else 0.0)


def _open3d_sor(P: np.ndarray, k: int, std_ratio: float) -> np.ndarray:
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    _, ind = pc.remove_statistical_outlier(nb_neighbors=k, std_ratio=std_ratio)
    keep = np.zeros(P.shape[0], dtype=bool)
    keep[np.asarray(ind, dtype=np.int64)] = True
    return keep


def _have_open3d() -> bool:
    try:
        import open3d  # noqa: F401
    except Exception:  # noqa: BLE001 - missing shared libraries raise OSError, not ImportError
        return False
    return True


def evaluate_outliers(
    data_dir: Any,
    methods: tuple[str, ...] = DEFAULT_METHODS,
    out: Any = None,
    *,
    fractions: tuple[float, ...] = (0.05, 0.1, 0.2),
    kinds: tuple[str, ...] = ("far", "near"),
    scans: tuple[tuple[str, str], ...] = SCANS,
    sequence_fractions: tuple[float, ...] = (0.1, 0.2, 0.3),
    seed: int = 0,
) -> list[dict]:
    """Run the outlier benchmark; return one row per (dataset, kind, fraction, method).

    Rows carry ``dataset, kind, fraction, method, params, precision, recall, f1, time_s,
    n_points`` (static) or ``theta_deg, p2s_mean, p2s_max_frame`` and per-frame lists
    (sequences; ``"sequence"`` in ``methods``). ``out`` writes ``<out>.md`` and ``<out>.csv``.
    """
    from .. import io, noise
    from ..geometry import pca_normals
    from ..outliers import remove_outliers

    data = Path(data_dir)
    if not data.is_dir():
        raise InvalidInputError(f"`data_dir` must be a folder; got {data}.")
    methods = tuple(methods)
    known = set(DEFAULT_METHODS)
    bad = [m for m in methods if m not in known]
    if bad:
        raise InvalidInputError(f"unknown method(s) {bad}; choose from {sorted(known)}.")
    o3d_ok = "open3d-sor" in methods and _have_open3d()
    rows: list[dict] = []
    if any(m in methods for m in ("rpca", "sor", "radius")):
        # load the compiled kernels (numba cache) outside the timings
        warm = np.random.default_rng(0).random((200, 3))
        for m in ("rpca", "sor", "radius"):
            remove_outliers(warm, method=m, k=10, return_points=False)
    for label, rel in progress(scans, desc="outlier scans", total=len(scans)):
        path = data / rel
        if not path.exists():
            continue
        P = io.read(path, kind="points").points
        N = pca_normals(P, 10, orient="none") if "near" in kinds else None
        for kind in kinds:
            for frac in fractions:
                Q, lab = noise.add_outliers(
                    P,
                    fraction=frac,
                    kind=kind,
                    rng=seed,
                    normals=N if kind == "near" else None,
                    shuffle=True,
                )
                base = {"dataset": label, "kind": kind, "fraction": frac, "n_points": Q.shape[0]}
                for m in methods:
                    if m in ("rpca", "sor", "radius"):
                        t0 = time.perf_counter()
                        r = remove_outliers(Q, method=m, k=10, return_points=False)
                        dt = time.perf_counter() - t0
                        rows.append(
                            _row(base, m, f"k=10, auto ({r.threshold:.3g})", ~r.keep, lab, dt)
                        )
                        if m == "rpca":
                            tau = _oracle_threshold(r.scores, lab)
                            rows.append(
                                _row(
                                    base,
                                    "rpca-oracle",
                                    f"k=10, tau={tau:.3g}",
                                    r.scores >= tau,
                                    lab,
                                    dt,
                                )
                            )
                    elif m == "sor-grid":
                        best = None
                        for k in _SOR_GRID[0]:
                            from ..outliers import sor_scores

                            t0 = time.perf_counter()
                            s = sor_scores(Q, k)
                            dt = time.perf_counter() - t0
                            for sr in _SOR_GRID[1]:
                                cand = _row(base, m, f"k={k}, std_ratio={sr}", s > sr, lab, dt)
                                if best is None or cand["f1"] > best["f1"]:
                                    best = cand
                        rows.append(best)
                    elif m == "open3d-sor" and o3d_ok:
                        t0 = time.perf_counter()
                        keep = _open3d_sor(Q, 10, 1.0)
                        dt = time.perf_counter() - t0
                        rows.append(_row(base, m, "nb_neighbors=10, std_ratio=1", ~keep, lab, dt))
    if "sequence" in methods:
        rows.extend(_evaluate_sequences(data, sequence_fractions, seed))
    if out is not None:
        _write(rows, out)
    return rows


def _oracle_threshold(scores: np.ndarray, labels: np.ndarray) -> float:
    """The threshold ``tau`` (remove ``score >= tau``) of best F1, chosen with the labels."""
    o = np.argsort(-scores, kind="stable")
    s = scores[o]
    tp = np.cumsum(labels[o])
    f1 = 2.0 * tp / (np.arange(1, s.size + 1) + max(int(np.count_nonzero(labels)), 1))
    # only cut between distinct scores: removing the top i+1 points must be a threshold
    valid = np.append(s[1:] < s[:-1], True)
    i = int(np.argmax(np.where(valid, f1, -1.0)))
    return float(s[i])


def _row(base: dict, method: str, params: str, removed, labels, dt: float) -> dict:
    p, r, f = _prf(np.asarray(removed, bool), labels)
    return {
        **base,
        "method": method,
        "params": params,
        "precision": round(p, 4),
        "recall": round(r, 4),
        "f1": round(f, 4),
        "time_s": round(dt, 3),
    }


def _evaluate_sequences(data: Path, fractions, seed: int) -> list[dict]:
    from ..metrics import point_to_surface, theta_deg
    from ..outliers import clean_sequence

    rows = []
    for label, rel in SEQUENCES:
        path = data / rel
        if not path.exists():
            continue
        z = np.load(path)
        V = np.asarray(z["vertices"], dtype=np.float64)
        F = np.asarray(z["faces"], dtype=np.int64)
        T, n, _ = V.shape
        for frac in fractions:
            rng = np.random.default_rng(seed)
            X = V.copy()
            lab = np.zeros((T, n), dtype=bool)
            for t in range(T):
                idx = rng.choice(n, int(round(frac * n)), replace=False)
                lab[t, idx] = True
                diag = float(np.linalg.norm(V[t].max(axis=0) - V[t].min(axis=0)))
                d = rng.standard_normal((idx.size, 3))
                d /= np.linalg.norm(d, axis=1, keepdims=True)
                X[t, idx] += d * rng.uniform(0.01, 0.05, (idx.size, 1)) * diag
            t0 = time.perf_counter()
            r = clean_sequence(X, k=10)
            dt = time.perf_counter() - t0
            keep = np.stack(r.keep)
            p, rc, f = _prf(~keep, lab)
            Y = np.stack([fr.points for fr in r.frames])
            for name, W, tt in (
                ("noisy input", X, 0.0),
                ("rpca low-rank E", r.low_rank, dt),
                ("rpca + weighted Laplacian", Y, dt),
            ):
                th = np.array([theta_deg(W[t], V[t], F) for t in range(T)])
                p2s = np.array([point_to_surface(W[t], V[t], F).distances.mean() for t in range(T)])
                row = {
                    "dataset": label,
                    "kind": "sequence",
                    "fraction": frac,
                    "n_points": n,
                    "method": name,
                    "params": "k=10, tau=1e-4" if tt else "",
                    "precision": round(p, 4) if name.endswith("Laplacian") else "",
                    "recall": round(rc, 4) if name.endswith("Laplacian") else "",
                    "f1": round(f, 4) if name.endswith("Laplacian") else "",
                    "time_s": round(tt, 3),
                    "theta_deg": round(float(th.mean()), 3),
                    "p2s_mean": float(f"{p2s.mean():.4g}"),
                    "theta_per_frame": [round(float(x), 3) for x in th],
                }
                rows.append(row)
    return rows


_COLS = (
    "dataset",
    "kind",
    "fraction",
    "method",
    "params",
    "precision",
    "recall",
    "f1",
    "time_s",
    "n_points",
    "theta_deg",
    "p2s_mean",
)


def _uses_labels(method: str) -> bool:
    """Rows whose parameters were chosen with the ground-truth labels (grid / oracle)."""
    return method.endswith("-grid") or method.endswith("-oracle")


def format_markdown(rows: list[dict]) -> str:
    """Markdown tables: static F1 per scan/kind/fraction/method, then the sequence results."""
    static = [r for r in rows if r.get("kind") != "sequence"]
    seq = [r for r in rows if r.get("kind") == "sequence"]
    out = []
    if static:
        out.extend(_summary(static))
        out.append(
            "| dataset | outliers | method | params | precision | recall | F1 | time (s) "
            "| points/s |"
        )
        out.append("|---|---|---|---|---|---|---|---|---|")
        # bold: the best F1 of a (scan, outliers) case among the methods that do not use labels
        best: dict[tuple, float] = {}
        for r in static:
            if not _uses_labels(r["method"]):
                key = (r["dataset"], r["kind"], r["fraction"])
                best[key] = max(best.get(key, -1.0), round(r["f1"], 3))
        for r in static:
            pps = r["n_points"] / r["time_s"] if r["time_s"] else float("inf")
            f1 = f"{r['f1']:.3f}"
            if not _uses_labels(r["method"]) and round(r["f1"], 3) == best.get(
                (r["dataset"], r["kind"], r["fraction"])
            ):
                f1 = f"**{f1}**"
            out.append(
                f"| {r['dataset']} | {r['kind']} {int(round(100 * r['fraction']))}% | "
                f"{r['method']} | {r['params']} | {r['precision']:.3f} | {r['recall']:.3f} | "
                f"{f1} | {r['time_s']:.2f} | {pps:,.0f} |"
            )
    if seq:
        out.append("")
        out.append(
            "| sequence | outliers | method | precision | recall | F1 | theta (deg) | "
            "mean point-to-surface | time (s) |"
        )
        out.append("|---|---|---|---|---|---|---|---|---|")
        for r in seq:
            out.append(
                f"| {r['dataset']} | {int(round(100 * r['fraction']))}% | {r['method']} | "
                f"{_fmt(r['precision'])} | {_fmt(r['recall'])} | {_fmt(r['f1'])} | "
                f"{r['theta_deg']:.3f} | {r['p2s_mean']:.4g} | {r['time_s']:.2f} |"
            )
    return "\n".join(out)


def _summary(static: list[dict]) -> list[str]:
    """One line per (scan, kind) at the 10 % fraction (or the middle one run): F1 of ``rpca``,
    ``rpca-oracle``, ``sor-grid``, ``open3d-sor`` and the time of ``rpca`` over Open3D's."""
    fracs = sorted({r["fraction"] for r in static})
    frac = 0.1 if 0.1 in fracs else fracs[len(fracs) // 2]
    cases: dict[tuple, dict] = {}
    for r in static:
        if r["fraction"] == frac:
            cases.setdefault((r["dataset"], r["kind"]), {})[r["method"]] = r
    if not any("rpca" in m for m in cases.values()):
        return []

    def f1(m: dict, name: str) -> str:
        return f"{m[name]['f1']:.3f}" if name in m else "-"

    lines = [
        f"Summary at {int(round(100 * frac))} % outliers (F1; the full table follows):",
        "",
        "| dataset | outliers | rpca | rpca-oracle | sor-grid | open3d-sor | rpca time / open3d |",
        "|---|---|---|---|---|---|---|",
    ]
    for (dataset, kind), m in cases.items():
        ratio = "-"
        if "rpca" in m and "open3d-sor" in m and m["open3d-sor"]["time_s"] > 0:
            ratio = f"{m['rpca']['time_s'] / m['open3d-sor']['time_s']:.1f}x"
        lines.append(
            f"| {dataset} | {kind} | {f1(m, 'rpca')} | {f1(m, 'rpca-oracle')} | "
            f"{f1(m, 'sor-grid')} | {f1(m, 'open3d-sor')} | {ratio} |"
        )
    lines.append("")
    return lines


def _fmt(v: Any) -> str:
    return f"{v:.3f}" if isinstance(v, float) else str(v)


def _write(rows: list[dict], out: Any) -> tuple[Path, Path]:
    return write_md_csv(
        out,
        "## Outlier removal\n\n"
        "Produced by `spectrageo evaluate outliers`; injected, labelled outliers on the shared "
        "scans (far: uniform in the enlarged bounding box; near: 1-3 spacings along the normal), "
        "F1 of the removed points. `sor-grid` is the best SOR over k x std_ratio chosen with "
        "the labels; `rpca-oracle` is the `rpca` scores cut at the best threshold chosen with "
        "the labels (how much the automatic threshold loses).\n\n" + format_markdown(rows),
        rows_to_csv(rows, _COLS),
    )
