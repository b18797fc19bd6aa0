"""Evaluation of the static mesh denoisers on noisy / ground-truth pairs (thesis Tables 5.4-5.5).

``spectrageo evaluate denoise [--data DIR] [--methods a,b] [--out FILE]`` runs every registered
denoiser (default settings) on every pair ``<data>/denoise/<Model>/{Noisy,Original}.*`` and reports
the metrics of Section 4.9 (theta, Dmean d, Dmax d, dist n, NMSVE, Dmean n, one-sided Hausdorff) and
the wall time. Optional peers run in the same session when their package is importable (the
``bench`` extra): PyMeshLab's two-step smoothing and Taubin smoothing, Open3D's Taubin smoothing.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from .._progress import progress
from ._tables import rows_to_csv, write_md_csv

#: columns of the table, in order
COLUMNS = (
    "pair",
    "method",
    "n_vertices",
    "theta_deg",
    "dmean",
    "dmax",
    "dist_n",
    "nmsve",
    "dmean_n",
    "hd_mean",
    "time_s",
)

#: peer methods run when their package can be imported
PEERS = ("pymeshlab-twostep", "pymeshlab-taubin", "open3d-taubin")


def _peer_available(name: str) -> bool:
    mod = name.split("-")[0]
    try:
        __import__(mod)
    except Exception:  # noqa: BLE001 - any import failure means "not available"
        return False
    return True


def _run_peer(name: str, V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Peer implementations with their default parameters (vertex order is kept by both)."""
    if name.startswith("pymeshlab"):
        import pymeshlab

        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32)))
        if name == "pymeshlab-twostep":
            ms.apply_coord_two_steps_smoothing()
        else:
            ms.apply_coord_taubin_smoothing()
        out = ms.current_mesh().vertex_matrix()
    else:
        import open3d as o3d

        m = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32))
        )
        out = np.asarray(m.filter_smooth_taubin(number_of_iterations=10).vertices)
    out = np.asarray(out, dtype=np.float64)
    if out.shape != V.shape:
        raise RuntimeError(f"{name} changed the vertex count ({V.shape[0]} -> {out.shape[0]}).")
    return out


def _row(pair: str, method: str, X, V0, F, dt: float, hd: bool) -> dict:
    from .. import metrics

    met = metrics.compare(X, V0, F, hausdorff_distance=hd)
    r = {"pair": pair, "method": method, "n_vertices": int(X.shape[0])}
    r.update({k: met.get(k, float("nan")) for k in COLUMNS[3:-1]})
    r["time_s"] = dt
    return r


def evaluate_denoise(
    data_dir,
    methods: list[str] | None = None,
    out=None,
    *,
    pairs: list[str] | None = None,
    peers: bool = True,
    hausdorff_distance: bool = True,
) -> list[dict]:
    """Run denoisers on every noisy / original pair and collect the metrics.

    Parameters
    ----------
    data_dir : path
        The shared data folder (holding ``denoise/``) or the ``denoise`` folder itself.
    methods : list of str, optional
        Registered denoisers and/or peers (:data:`PEERS`); default every registered denoiser plus
        the importable peers. ``"<method>+coarse"`` runs the method after the TSGSP coarse step.
    out : path, optional
        Writes ``<out>.md`` and ``<out>.csv`` atomically (a ``.md``/``.csv`` suffix is dropped).
    pairs : list of str, optional
        Subset of pair names (e.g. ``["Fandisk0.7"]``).
    peers : bool
        Include the importable peers when ``methods`` is None.
    hausdorff_distance : bool
        Compute the (costliest) Hausdorff column.

    Returns
    -------
    list of dict, one row per (pair, method) with the keys of :data:`COLUMNS`; the noisy input is
    reported as method ``"noisy"``.
    """
    from .. import denoise, io
    from ..datasets import denoise_pairs
    from ..denoise._registry import warm_up

    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise InvalidInputError(f"`data_dir` must be a folder; got {data_dir}.")
    found = denoise_pairs(data_dir)
    if not found:
        raise InvalidInputError(f"no noisy/original pairs found under {data_dir}.")
    if pairs is not None:
        unknown = sorted(set(pairs) - {p[0] for p in found})
        if unknown:
            raise InvalidInputError(f"unknown pairs {unknown}; available: {[p[0] for p in found]}.")
        found = [p for p in found if p[0] in pairs]
    if methods is None:
        methods = denoise.available() + ([p for p in PEERS if _peer_available(p)] if peers else [])
    methods = list(methods)
    own = []  # registered denoisers among the methods (warmed up before timing)
    for m in methods:
        base = m[: -len("+coarse")] if m.endswith("+coarse") else m
        if base in PEERS:
            if not _peer_available(base):
                raise InvalidInputError(
                    f"peer {base!r} is not installed (pip install 'spectrageo[bench]')."
                )
        else:
            denoise.get(base)
            own.append(base)
    rows: list[dict] = []
    for name, noisy_path, orig_path in progress(found, desc="denoise pairs", total=len(found)):
        noisy = io.read_mesh(noisy_path)
        orig = io.read_mesh(orig_path)
        V, F, V0 = noisy.vertices, noisy.faces, orig.vertices
        if V.shape != V0.shape:
            raise InvalidInputError(f"pair {name}: noisy and original vertex counts differ.")
        rows.append(_row(name, "noisy", V, V0, F, 0.0, hausdorff_distance))
        if own:  # one-time compilation (numba caches) kept out of the first pair's timings
            warm_up(own, V, F)
            own = []
        for m in methods:
            pre = m.endswith("+coarse")
            base = m[: -len("+coarse")] if pre else m
            t0 = time.perf_counter()
            if base in PEERS:
                if pre:
                    from ..denoise.tsgsp import coarse

                    X = _run_peer(base, coarse(V, F), F)
                else:
                    X = _run_peer(base, V, F)
            else:
                X = denoise.denoise(V, F, method=base, pre="coarse" if pre else None)
            dt = time.perf_counter() - t0
            rows.append(_row(name, m, X, V0, F, dt, hausdorff_distance))
    if out is not None:
        write_tables(rows, out)
    return rows


def _fmt(key: str, v) -> str:
    if isinstance(v, str):
        return v
    if key == "n_vertices":
        return str(int(v))
    if key in ("theta_deg",):
        return f"{v:.2f}"
    if key == "time_s":
        return f"{v:.2f}"
    if key == "nmsve":
        return f"{v:.3e}"
    return f"{v:.4g}"


def format_markdown(rows: list[dict]) -> str:
    """Markdown table of :func:`evaluate_denoise` rows (the best theta per pair in bold)."""
    head = (
        "| pair | method | n | theta (deg) | Dmean d | Dmax d | dist n | NMSVE | Dmean n "
        "| HD mean | time (s) |"
    )
    lines = [head, "|" + "---|" * len(COLUMNS)]
    best: dict[str, float] = {}
    for r in rows:
        if r["method"] != "noisy":
            best[r["pair"]] = min(best.get(r["pair"], np.inf), r["theta_deg"])
    for r in rows:
        cells = [_fmt(k, r[k]) for k in COLUMNS]
        if r["method"] != "noisy" and r["theta_deg"] == best.get(r["pair"]):
            cells[3] = f"**{cells[3]}**"
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


#: theta (degrees) of GNF and TSGSP in the thesis' Table 5.4 for the models of the shared pairs
#: (its own noise realisations, which are not available).
THESIS_THETA = {
    "Block0.4": (3.572, 3.3026),
    "Fandisk0.7": (6.3721, 6.0669),
    "SharpSphere0.3": (10.1697, 6.2407),
    "Twelve0.5Impulsive": (2.7542, 2.6543),
}


def format_summary(rows: list[dict]) -> str:
    """TSGSP against GNF per pair (theta and time ratio), with the thesis' Table 5.4 values."""
    by: dict[str, dict] = {}
    for r in rows:
        by.setdefault(r["pair"], {})[r["method"]] = r
    lines = [
        "| pair | tsgsp theta | gnf theta | tsgsp time / gnf time | thesis tsgsp | thesis gnf |",
        "|---|---|---|---|---|---|",
    ]
    for pair, m in by.items():
        if "tsgsp" not in m or "gnf" not in m:
            continue
        t, g = m["tsgsp"], m["gnf"]
        ratio = f"{t['time_s'] / g['time_s']:.2f}" if g["time_s"] > 0 else "-"
        th_g, th_t = THESIS_THETA.get(pair, (None, None))
        lines.append(
            f"| {pair} | {t['theta_deg']:.2f} | {g['theta_deg']:.2f} | {ratio} | "
            f"{'-' if th_t is None else f'{th_t:.2f}'} | {'-' if th_g is None else f'{th_g:.2f}'} |"
        )
    return "\n".join(lines) if len(lines) > 2 else ""


def format_csv(rows: list[dict]) -> str:
    """CSV text of the rows (full precision)."""
    return rows_to_csv(rows, COLUMNS)


def write_tables(rows: list[dict], out) -> tuple[Path, Path]:
    """Write ``<out>.md`` and ``<out>.csv`` atomically; returns both paths."""
    return write_md_csv(
        out,
        "## Static mesh denoising\n\n"
        "Produced by `spectrageo evaluate denoise`; every method with its default settings.\n\n"
        + _summary_block(rows)
        + format_markdown(rows)
        + "\n",
        format_csv(rows),
    )


def _summary_block(rows: list[dict]) -> str:
    table = format_summary(rows)
    if not table:
        return ""
    return (
        "TSGSP against GNF (the thesis columns are Table 5.4's values on its own noise "
        "realisations of the same models; compare the rankings):\n\n" + table + "\n\n"
    )


__all__ = [
    "COLUMNS",
    "PEERS",
    "THESIS_THETA",
    "evaluate_denoise",
    "format_csv",
    "format_markdown",
    "format_summary",
    "write_tables",
]
