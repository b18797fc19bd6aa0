"""Outlier removal per scan type (``spectrageo evaluate outliers``, rows with ``suite`` =
``"scan-types"``).

Per case of the registry's ``outliers-scantypes`` task: ``clean`` (the scan, or its points within
:data:`REAL_OUTLIER_SPACINGS` of the reference surface: share removed and the largest connected
group of removed points), ``real`` (labels from the reference surface), ``injected`` (half uniform
in the padded box, half 5-15 spacings off the surface along the normals, at 10 % and 30 %) and
``bands`` (3 % each at 1-3, 3-5, 5-15 spacings: recall per band). Peers in the same run: SOR and
radius removal at the defaults of :func:`spectrageo.outliers.remove_outliers`, Open3D's SOR at its
tutorial setting, PCL's tutorial SOR, and their per-case oracles.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..datasets._split_outliers import OUTLIER_SCAN_TYPES, OUTLIER_SCAN_TYPES_IN_REPO
from ..datasets.splits import cases as _cases

__all__ = [
    "REAL_OUTLIER_SPACINGS",
    "REPO_DATA",
    "SCAN_TYPE_CASES",
    "evaluate_scan_types",
    "real_labels",
    "scan_path",
]

#: (name, file, split) of the cases, from the split registry
SCAN_TYPE_CASES = tuple((c.name, c.file, c.split) for c in _cases("outliers-scantypes"))
#: a point farther than this many spacings from the reference surface is a real outlier
#: (docs/decisions.md#outliers-real-labels)
REAL_OUTLIER_SPACINGS = 3.0
#: distance bands of the ``bands`` case, in spacings
BANDS = ((1.0, 3.0), (3.0, 5.0), (5.0, 15.0))
INJECTED_FRACTIONS = (0.1, 0.3)
_REFERENCE = "meshes/stanford-bunny.obj"
#: the source tree's ``benchmarks/data``: the folder of the cases with ``root="repo"`` (absent
#: from an installed package, where those cases are skipped)
REPO_DATA = Path(__file__).resolve().parents[3] / "benchmarks" / "data"


def scan_path(data: Path, rel: str) -> Path:
    """The file of a scan-type case: under ``data`` (the shared data), or under
    :data:`REPO_DATA` for the files the repository ships (``OUTLIER_SCAN_TYPES_IN_REPO``)."""
    return (REPO_DATA if rel in OUTLIER_SCAN_TYPES_IN_REPO else Path(data)) / rel


def real_labels(data: Path, rel: str) -> tuple[np.ndarray, np.ndarray, float] | None:
    """``(points, labels, spacing)`` of a bunny range scan in the ``bun.conf`` frame; labels:
    farther than :data:`REAL_OUTLIER_SPACINGS` nearest-neighbour spacings from the reference."""
    from scipy.spatial import cKDTree

    from .. import io
    from ..metrics import point_to_surface
    from .register import bunny_scans

    if not rel.startswith("scans/bunny/") or not (data / _REFERENCE).is_file():
        return None
    name = Path(rel).name.removesuffix(".ply.gz")
    for nm, P, T in bunny_scans(data):
        if nm == name:
            W = P @ T[:3, :3].T + T[:3, 3]
            ref = io.read(data / _REFERENCE)
            d = point_to_surface(W, ref.vertices, ref.faces).distances
            h = float(np.median(cKDTree(W).query(W, 2)[0][:, 1]))
            return W, d > REAL_OUTLIER_SPACINGS * h, h
    return None


def _largest_group(P: np.ndarray, removed: np.ndarray, h: float) -> int:
    """Points in the largest group of removed points connected within ``3 h``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    R = P[removed]
    if R.shape[0] < 2:
        return int(R.shape[0])
    pairs = cKDTree(R).query_pairs(3.0 * h, output_type="ndarray")
    m = R.shape[0]
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    _, lab = connected_components(g, directed=False)
    return int(np.bincount(lab).max())


def _inject(P: np.ndarray, N: np.ndarray, frac: float, seed: int, bands=None):
    """``(points, labels, band index or -1, row of P or -1)``: far + near (5-15) at ``frac``, or
    the bands."""
    from .. import noise

    parts = [(P, np.zeros(P.shape[0], bool), np.full(P.shape[0], -1))]
    spec = (
        [("near", b, frac) for b in bands]
        if bands
        else [("far", None, frac / 2), ("near", (5.0, 15.0), frac / 2)]
    )
    for i, (kind, dist, f) in enumerate(spec):
        kw = {"normals": N, "distance": dist} if kind == "near" else {}
        Q, lab = noise.add_outliers(P, fraction=f, kind=kind, rng=seed + i, **kw)
        parts.append((Q[lab], np.ones(int(lab.sum()), bool), np.full(int(lab.sum()), i)))
    Q = np.concatenate([p[0] for p in parts])
    order = np.random.default_rng(seed).permutation(Q.shape[0])
    lab = np.concatenate([p[1] for p in parts])[order]
    band = np.concatenate([p[2] for p in parts])[order]
    src = np.concatenate([np.arange(P.shape[0]), np.full(Q.shape[0] - P.shape[0], -1)])[order]
    return Q[order], lab, band, src


def _methods(Q: np.ndarray, lab: np.ndarray, viewpoint, o3d_ok: bool, grid=None):
    """``(method, params, removed, seconds)`` of ours and the peers (oracles only with labels);
    ``grid``: the organized frame's :class:`~spectrageo.outliers.OrganizedGrid` for ``Q``."""
    from ..outliers import RPCAOptions, detect_outliers
    from ._outliers_common import PCL_MEAN_K, _open3d_sor, _oracle_threshold

    out = []
    runs = [("rpca", RPCAOptions(viewpoint=viewpoint, grid=grid), "defaults")]
    if grid is not None:
        runs.append(("rpca (no grid)", RPCAOptions(viewpoint=viewpoint), "defaults, no grid"))
    if viewpoint is not None:
        runs.append(("rpca (no viewpoint)", RPCAOptions(), "defaults, no viewpoint"))
    for name, opts, params in runs:
        t0 = time.perf_counter()
        r = detect_outliers(Q, options=opts)
        out.append((name, f"{params} ({r.threshold:.3g})", ~r.keep, time.perf_counter() - t0))
    for m in ("sor", "radius"):
        t0 = time.perf_counter()
        r = detect_outliers(Q, method=m, k=10)
        dt = time.perf_counter() - t0
        out.append((m, f"k=10, default ({r.threshold:.3g})", ~r.keep, dt))
        if lab.any():
            tau = _oracle_threshold(r.scores, lab)
            out.append((f"{m}-oracle", f"k=10, {tau:.3g}", r.scores >= tau, dt))
    t0 = time.perf_counter()
    r = detect_outliers(Q, method="sor", k=PCL_MEAN_K)
    out.append(("pcl-sor", "meanK=50, std=1", ~r.keep, time.perf_counter() - t0))
    if o3d_ok:
        t0 = time.perf_counter()
        keep = _open3d_sor(Q, 20, 2.0)
        out.append(("open3d-sor", "nb=20, std=2 (tutorial)", ~keep, time.perf_counter() - t0))
    return out


def evaluate_scan_types(data_dir, *, splits=("tuning", "validation"), seed: int = 0) -> list:
    """Rows of the scan-type benchmark (module docstring) on the cases of ``splits``; none when
    ``data_dir`` holds none of its shared-data scans (the repository's files only extend it)."""
    from scipy.spatial import cKDTree

    from .. import io
    from ..geometry import pca_normals
    from ..outliers import OrganizedGrid
    from ._outliers_common import _have_open3d, _row

    data = Path(data_dir)
    shared = [rel for _n, rel, _s in SCAN_TYPE_CASES if rel not in OUTLIER_SCAN_TYPES_IN_REPO]
    if shared and not any((data / rel).exists() for rel in shared):
        return []
    o3d_ok = _have_open3d()
    rows: list[dict] = []
    for name, rel, split in SCAN_TYPE_CASES:
        path = scan_path(data, rel)
        if split not in splits:
            continue
        if not path.exists():
            if rel in OUTLIER_SCAN_TYPES_IN_REPO:
                print(f"scan types: {name} skipped ({path} not found)", flush=True)
            continue
        stype, viewpoint = OUTLIER_SCAN_TYPES[rel]
        real = real_labels(data, rel)
        pixel = shape = None
        if real is not None:
            raw, rl, h = real
            P = raw[~rl]
        else:
            pc = io.read(path, kind="points")
            P = pc.points
            h = float(np.median(cKDTree(P).query(P, 2)[0][:, 1]))
            shape, pixel = _organized(path, pc)
        N = pca_normals(P, 10, orient="none")
        every = np.arange(P.shape[0])
        tests = [("clean", 0.0, P, np.zeros(P.shape[0], bool), None, every)]
        if real is not None:
            tests.append(("real", float(rl.mean()), raw, rl, None, every))
        for frac in INJECTED_FRACTIONS:
            Q, lab, _, src = _inject(P, N, frac, seed)
            tests.append(("injected", frac, Q, lab, None, src))
        Q, lab, band, src = _inject(P, N, 0.03, seed, bands=BANDS)
        tests.append(("bands", 0.09, Q, lab, band, src))
        for kind, frac, Q, lab, band, src in tests:
            base = {"suite": "scan-types", "split": split, "scan_type": stype, "dataset": name,
                    "kind": kind, "fraction": round(frac, 5), "n_points": Q.shape[0],
                    "n_outliers": int(lab.sum())}  # fmt: skip
            grid = None
            if pixel is not None:
                grid = OrganizedGrid(shape, np.where(src >= 0, pixel[np.maximum(src, 0)], -1))
            for m, params, removed, dt in _methods(Q, lab, viewpoint, o3d_ok, grid):
                row = _row(base, m, params, removed, lab, dt)
                row["removed"] = round(float(removed.mean()), 5)
                if kind == "clean":
                    row["flagged"] = round(float(removed.mean()), 4)
                    row["largest_group"] = _largest_group(Q, removed, h)
                if band is not None:
                    for i, (lo, hi) in enumerate(BANDS):
                        sel = band == i
                        row[f"recall_{lo:g}_{hi:g}"] = round(float(removed[sel].mean()), 4)
                rows.append(row)
    return rows


def _organized(path: Path, pc) -> tuple:
    """``(shape, pixel of each point)`` of an organized PCD frame, else ``(None, None)``."""
    from ..io._pcd import read_pcd_header

    if not path.name.lower().endswith((".pcd", ".pcd.gz")):
        return None, None
    hdr = read_pcd_header(path)
    if not hdr.organized:
        return None, None
    pixel = pc.attributes.get("source_index", np.arange(pc.points.shape[0]))
    return (hdr.height, hdr.width), np.asarray(pixel, dtype=np.int64)


_DEFAULT_PEERS = ("sor", "radius", "pcl-sor", "open3d-sor")
_ORACLES = ("sor-oracle", "radius-oracle")


def format_scan_types(rows: list) -> list:
    """Markdown lines: per split, scan type and test, the mean over cases of ``rpca`` against the
    best peer at defaults and the best per-case oracle (F1; ``clean``: share removed)."""
    groups: dict[tuple, dict] = {}
    for r in rows:
        frac = r["fraction"] if r["kind"] in ("injected", "clean") else 0
        key = (r["split"], r["scan_type"], r["kind"], frac)
        groups.setdefault(key, {}).setdefault(r["method"], []).append(r)
    out = [
        "Scan types (mean over the cases of a split; clean: share removed, largest connected "
        "group removed; bands: recall at 1-3 / 3-5 / 5-15 spacings):",
        "",
        "| split | scan type | test | cases | rpca | best peer (defaults) | best oracle | rpca "
        "P / R |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (split, stype, kind, frac), ms in sorted(groups.items()):

        def mean(m, col, ms=ms):
            return float(np.mean([r[col] for r in ms[m]])) if m in ms else float("nan")

        n = len(ms.get("rpca", []))
        test = kind if kind in ("clean", "bands") else f"{kind} {round(100 * frac)} %"
        n_out = sum(r["n_outliers"] for r in ms.get("rpca", []))
        if kind == "real":
            test = f"real ({n_out} outliers)"
        if kind == "clean":
            peers = {m: mean(m, "flagged") for m in _DEFAULT_PEERS if m in ms}
            grp = max(r["largest_group"] for r in ms["rpca"])
            cells = (f"{100 * mean('rpca', 'flagged'):.2f} % (group {grp})",
                     ", ".join(f"{m} {100 * v:.2f} %" for m, v in peers.items()), "-", "-")  # fmt: skip
        elif kind == "bands":
            cols = [c for c in ms["rpca"][0] if c.startswith("recall_")]

            def bands(m, cols=cols):
                return " / ".join(f"{mean(m, c):.2f}" for c in cols)

            best = max(_DEFAULT_PEERS, key=lambda m: mean(m, "f1") if m in ms else -1)
            cells = (bands("rpca"), f"{best} {bands(best)}", "-", "-")
        elif kind == "real":  # few labels: pooled over the cases

            def found(m, ms=ms):
                return sum(round(r["recall"] * r["n_outliers"]) for r in ms[m])

            def pooled(m, n_out=n_out):
                return f"found {found(m)} of {n_out}, removed {100 * mean(m, 'removed'):.2f} %"

            peers = [m for m in _DEFAULT_PEERS if m in ms]
            best = max(peers, key=lambda m: (found(m), -mean(m, "removed")))
            cells = (pooled("rpca"), f"{best}: {pooled(best)}", "-", "-")
        else:
            peers = {m: mean(m, "f1") for m in _DEFAULT_PEERS if m in ms}
            bp = max(peers, key=peers.get)
            orc = {m: mean(m, "f1") for m in _ORACLES if m in ms}
            bo = max(orc, key=orc.get) if orc else None
            cells = (
                f"{mean('rpca', 'f1'):.3f}",
                f"{bp} {peers[bp]:.3f}",
                f"{bo} {orc[bo]:.3f}" if bo else "-",
                f"{mean('rpca', 'precision'):.3f} / {mean('rpca', 'recall'):.3f}",
            )
        out.append(f"| {split} | {stype} | {test} | {n} | " + " | ".join(cells) + " |")
    out.append("")
    return out
