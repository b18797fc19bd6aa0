"""``spectrageo evaluate compress``: rate-distortion of the .sgc codecs against Draco and zstd.

Per mesh of :data:`SPLITS` and rate point: bits per vertex of the whole file, RMS error,
symmetric Hausdorff distance and symmetric RMS vertex-to-surface distance over the diagonal, NMSVE (Eq. 4.32), theta (order-keeping methods
only), order kept, encode / decode times. Methods: ``spectral`` (:data:`STEPS`),
``spectral-reorder`` (:data:`STEPS`), ``predictive`` and ``predictive-reorder``
(:data:`MAX_ERRORS`), when named ``auto`` and ``auto-reorder`` (the default of
:func:`spectrageo.compress.encode`, at :data:`MAX_ERRORS`), ``feature`` and ``uniform-delta`` (Algorithm 9 and its baseline, at
:data:`GEOMETRY_BPV` through the rate control), ``saliency`` (Algorithm 10); peers when installed:
Draco (DracoPy, :data:`DRACO_BITS`, default mode at compression level 10 and
order-preserving) and quantisation + zstd.

Splits (:mod:`spectrageo.datasets.splits`, task ``compress``): the codecs' defaults were chosen on
:data:`TUNING_SPLIT`; :data:`VALIDATION_SPLIT` is held out for them but not for the connectivity
coder (docs/decisions.md#compress-connectivity). :data:`LARGE` runs only with ``large=True``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from .._progress import progress
from ..datasets.splits import COMPRESS_LARGE
from ..datasets.splits import cases as _cases
from ..datasets.splits import files as _files
from ._tables import (
    check_names,
    have,
    markdown_table,
    rate_at_error,
    unmet_request,
    write_rate_outputs,
)

#: the splits of the split registry's ``compress`` task (:mod:`spectrageo.datasets.splits`)
TUNING_SPLIT = _files("compress", "tuning")
VALIDATION_SPLIT = tuple(f for f in _files("compress", "validation") if f not in COMPRESS_LARGE)
LARGE = COMPRESS_LARGE
SPLITS = {"tuning": TUNING_SPLIT, "validation": VALIDATION_SPLIT}
METHODS = (
    "spectral",
    "spectral-reorder",
    "predictive",
    "predictive-reorder",
    "feature",
    "uniform-delta",
    "saliency",
)
#: run only when named: ``compress.encode(method="auto")`` at :data:`MAX_ERRORS` (its two
#: methods are in :data:`METHODS` already)
EXTRA_METHODS = ("auto", "auto-reorder")
PEERS = ("draco", "draco-ordered", "quant-zstd")
STEPS = {
    "spectral": (3e-3, 1e-3, 3e-4, 1e-4),
    "spectral-reorder": (1e-2, 3e-3, 1e-3, 3e-4, 1e-4),
}
#: ``max_error`` requests of the predictive points: about 1 to 30 bits per vertex (reordered)
MAX_ERRORS = (2e-2, 1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4, 5e-5, 2e-5, 1e-5, 5e-6, 2e-6)
#: geometry rates (bits per vertex above the connectivity) of the feature, uniform-delta and
#: saliency points
GEOMETRY_BPV = (2, 3, 4, 6, 8, 12, 16, 20)
DRACO_BITS = (6, 7, 8, 10, 12, 14, 16)
#: Draco's compression level in its default (reordering) mode: its strongest
DRACO_LEVEL = 10
ZSTD_BITS = (8, 10, 12, 14, 16)
COLUMNS = (
    "split",
    "model",
    "n_vertices",
    "method",
    "setting",
    "bpv",
    "conn_bpv",
    "rms",
    "hausdorff",
    "rms_surface",
    "nmsve",
    "theta_deg",
    "order_kept",
    "encode_s",
    "decode_s",
    "sent_share",
)


def _metrics(V, F, V2, F2, ordered: bool) -> dict:
    from ..metrics import nmsve, surface_distance_per_vertex, theta_deg

    diag = float(np.linalg.norm(V.max(0) - V.min(0))) or 1.0
    # exact vertex-to-surface distances both ways (vertices used by a face)
    d = np.r_[
        surface_distance_per_vertex(V2[np.unique(F2)], V, F),
        surface_distance_per_vertex(V[np.unique(F)], V2, F2),
    ]
    out = {
        "hausdorff": float(d.max()) / diag,
        "rms_surface": float(np.sqrt(np.mean(d * d))) / diag,
    }
    if ordered:
        out["rms"] = float(np.sqrt(np.mean(np.sum((V2 - V) ** 2, axis=1)))) / diag
        out["nmsve"] = nmsve(V2, V, F)
        out["theta_deg"] = theta_deg(V2, V, F)
    else:
        out["rms"] = out["nmsve"] = out["theta_deg"] = float("nan")
    return out


def _ours(method: str, V, F, step: float | None, bpv: float | None = None, max_error=None):
    from .. import compress

    opts = {}
    name = method
    if method == "uniform-delta":
        name, opts = "feature", {"feature_fraction": 1.0, "ratio": 1.0}
    elif method.endswith("-reorder"):
        name, opts = method.removesuffix("-reorder"), {"reorder": True}
    t0 = time.perf_counter()
    data = compress.encode(V, F, method=name, step=step, bpv=bpv, max_error=max_error, **opts)
    t1 = time.perf_counter()
    V2, F2 = compress.decode(data)
    t2 = time.perf_counter()
    inf = compress.info(data)
    share = inf["parameters"].get("sent_share", float("nan"))
    conn = inf["connectivity_bpv"]
    return len(data), V2, F2, t1 - t0, t2 - t1, not opts.get("reorder", False), conn, share


def _connectivity_bpv(V, F) -> float:
    """Bits per vertex of the order-keeping connectivity chunk (what ``info`` reports)."""
    from ..compress import _connectivity

    return 8.0 * len(_connectivity.encode_faces(F)) / V.shape[0]


def _draco(V, F, bits: int, ordered: bool):
    import DracoPy

    t0 = time.perf_counter()
    data = DracoPy.encode(
        V,
        F.astype(np.uint32),
        quantization_bits=bits,
        compression_level=1 if ordered else DRACO_LEVEL,
        preserve_order=ordered,
    )
    t1 = time.perf_counter()
    m = DracoPy.decode(data)
    t2 = time.perf_counter()
    V2 = np.asarray(m.points, dtype=np.float64)
    F2 = np.asarray(m.faces, dtype=np.int64).reshape(-1, 3)
    same = ordered and V2.shape == V.shape and np.array_equal(F2, F)
    return len(data), V2, F2, t1 - t0, t2 - t1, bool(same), float("nan"), float("nan")


def _quant_zstd(V, F, bits: int):
    import zstandard

    t0 = time.perf_counter()
    lo, hi = V.min(0), V.max(0)
    rng = float((hi - lo).max()) or 1.0
    q = np.rint((V - lo) / rng * ((1 << bits) - 1)).astype(np.uint32 if bits > 16 else np.uint16)
    cz = zstandard.ZstdCompressor(level=19)
    blob_v = cz.compress(q.T.copy().tobytes())
    blob_f = cz.compress(F.astype(np.int32).tobytes())
    t1 = time.perf_counter()
    dz = zstandard.ZstdDecompressor()
    q2 = np.frombuffer(dz.decompress(blob_v), dtype=q.dtype).reshape(3, -1).T
    F2 = np.frombuffer(dz.decompress(blob_f), dtype=np.int32).reshape(-1, 3).astype(np.int64)
    V2 = q2 * (rng / ((1 << bits) - 1)) + lo
    t2 = time.perf_counter()
    n_bytes = len(blob_v) + len(blob_f) + 32  # + origin and range
    return n_bytes, V2, F2, t1 - t0, t2 - t1, True, 8.0 * len(blob_f) / V.shape[0], float("nan")


def _is_cad(path: str) -> bool:
    return path.startswith("cad/") or any(c.file == path for c in _cases("compress", group="cad"))


def evaluate(
    data_dir,
    methods=None,
    out=None,
    *,
    splits=tuple(SPLITS),
    large: bool = False,
    peers: bool = True,
) -> list[dict]:
    """Run the compression evaluation; returns one row (dict over :data:`COLUMNS`) per point."""
    from .. import io

    data = Path(data_dir)
    methods = check_names(methods or METHODS + PEERS, METHODS + EXTRA_METHODS + PEERS, "method")
    splits = check_names(splits, sorted(SPLITS), "split")
    todo = [(s, p) for s in splits for p in SPLITS[s]] + (
        [("large", p) for p in LARGE] if large else []
    )
    rows = []
    for split, rel in progress(todo, desc="compress", total=len(todo)):
        path = data / rel
        if not path.exists():
            continue
        mesh = io.read_mesh(path)
        V, F = mesh.vertices, mesh.faces
        n = V.shape[0]
        jobs = []
        conn_bpv = None
        for m in methods:
            if m in ("feature", "uniform-delta") and not _is_cad(rel):
                continue
            if m == "saliency" and n > 30000:
                continue
            if m in ("feature", "uniform-delta", "saliency"):
                if conn_bpv is None:
                    conn_bpv = _connectivity_bpv(V, F)
                jobs += [
                    (m, f"bpv=conn+{g:g}", _ours, (m, V, F, None, conn_bpv + g))
                    for g in GEOMETRY_BPV
                ]
            elif m.startswith(("predictive", "auto")):
                jobs += [
                    (m, f"max_error={e:g}", _ours, (m, V, F, None, None, e)) for e in MAX_ERRORS
                ]
            elif m in STEPS:
                jobs += [(m, f"step={s:g}", _ours, (m, V, F, s)) for s in STEPS[m]]
            elif m.startswith("draco") and peers and have("DracoPy"):
                o = m == "draco-ordered"
                jobs += [(m, f"q={b}", _draco, (V, F, b, o)) for b in DRACO_BITS]
            elif m == "quant-zstd" and peers:
                jobs += [(m, f"q={b}", _quant_zstd, (V, F, b)) for b in ZSTD_BITS]
        for m, setting, fn, fargs in jobs:
            try:
                n_bytes, V2, F2, te, td, ordered, conn, share = fn(*fargs)
            except InvalidInputError as exc:
                if not unmet_request(exc):
                    raise
                continue  # a rate the codec cannot meet on this mesh: no point
            try:
                quality = _metrics(V, F, V2, F2, ordered)
            except InvalidInputError as exc:
                if "theta is undefined" not in str(exc):
                    raise
                continue  # the decoded mesh collapsed (every face degenerate) at this rate
            row = {
                "split": split,
                "model": Path(rel).name.split(".")[0],
                "n_vertices": n,
                "method": m,
                "setting": setting,
                "bpv": 8.0 * n_bytes / n,
                "conn_bpv": conn,
                "order_kept": ordered,
                "encode_s": te,
                "decode_s": td,
                "sent_share": share,
                **quality,
            }
            rows.append(row)
    if out is not None:
        write_rate_outputs(
            out,
            format_markdown(rows),
            rows,
            COLUMNS,
            x="bpv",
            y="hausdorff",
            xlabel="bits per vertex (whole file)",
            ylabel="symmetric Hausdorff / diagonal",
        )
    return rows


def equal_error_rows(rows: list[dict], key: str = "hausdorff") -> list[dict]:
    """Our size at each Draco point's error ``key`` (``hausdorff`` or ``rms_surface``): order
    kept against ``draco-ordered`` (best of the order-keeping methods), the best reordering one
    against ``draco``."""
    ours_ordered = ("spectral", "predictive", "feature", "saliency", "auto")
    ours_reorder = ("spectral-reorder", "predictive-reorder", "auto-reorder")
    out = []
    for split, model in dict.fromkeys((r["split"], r["model"]) for r in rows):
        mine = [r for r in rows if (r["split"], r["model"]) == (split, model)]
        for peer, ours in (("draco-ordered", ours_ordered), ("draco", ours_reorder)):
            for p in (r for r in mine if r["method"] == peer):
                best, who = float("nan"), "-"
                for m in ours:
                    b = rate_at_error(
                        [(r["bpv"], r[key]) for r in mine if r["method"] == m], p[key]
                    )
                    if np.isfinite(b) and not b >= best:
                        best, who = b, m
                out.append(
                    {
                        "split": split,
                        "model": model,
                        "peer": f"{peer} {p['setting']}",
                        key: p[key],
                        "peer_bpv": p["bpv"],
                        "ours": who,
                        "ours_bpv": best,
                        "ratio": best / p["bpv"] if np.isfinite(best) else float("nan"),
                    }
                )
    return out


def feature_rows(rows: list[dict]) -> list[dict]:
    """``feature`` against ``uniform-delta`` at the same requested rate, one row per mesh and
    rate where both met it."""
    out = []
    for split, model in dict.fromkeys((r["split"], r["model"]) for r in rows):
        mine = [r for r in rows if (r["split"], r["model"]) == (split, model)]
        uni = {r["setting"]: r for r in mine if r["method"] == "uniform-delta"}
        for f in (r for r in mine if r["method"] == "feature"):
            u = uni.get(f["setting"])
            if u is None:
                continue
            better = [
                name
                for name, key in (("hausdorff", "hausdorff"), ("theta", "theta_deg"))
                if f[key] < u[key] and not np.isclose(f[key], u[key], rtol=1e-9)
            ]
            worse = [key for key in ("hausdorff", "theta_deg") if f[key] > u[key] * (1 + 1e-9)]
            verdict = (
                "both"
                if len(better) == 2
                else better[0]
                if better
                else ("same" if not worse else "neither")
            )
            out.append(
                {
                    "split": split,
                    "model": model,
                    "rate": f["setting"].replace("bpv=", ""),
                    "feature_bpv": f["bpv"],
                    "uniform_bpv": u["bpv"],
                    "sent_share": f["sent_share"],
                    "feature_hausdorff": f["hausdorff"],
                    "uniform_hausdorff": u["hausdorff"],
                    "feature_theta": f["theta_deg"],
                    "uniform_theta": u["theta_deg"],
                    "feature_better": verdict,
                }
            )
    return out


def format_markdown(rows: list[dict]) -> str:
    cols = tuple(c for c in COLUMNS if c not in ("split", "n_vertices"))
    splits = sorted({r["split"] for r in rows})
    lines = [
        "## Static mesh compression",
        "",
        "Produced by `spectrageo evaluate compress` (splits run: "
        + (", ".join(splits) or "none")
        + "). `bpv` counts the whole file, connectivity included; `rms` and `hausdorff` "
        "(symmetric, surface samples) are fractions of the bounding-box diagonal; `theta_deg` and "
        "`nmsve` only where the vertex order is kept. `draco` lets Draco reorder vertices, "
        "`draco-ordered` keeps the order; `quant-zstd` is uniform quantisation + zstd. The "
        "geometry codecs' defaults were chosen on the tuning split (fandisk, partLp) only; the "
        "connectivity coder's constants on the tuning meshes of benchmarks/connectivity.py, "
        "which include every mesh here, so the validation rows are not held out for it.",
        "",
        "",
        "### Size at Draco's error",
        "",
        "Our bits per vertex at the symmetric Hausdorff error of each Draco setting, interpolated "
        "log-log on our rate curve (`-` where Draco's error lies outside it); `ratio` = ours / "
        "Draco. Order kept: the best of spectral, predictive, feature and saliency against "
        "Draco's order-preserving mode; the better of `spectral-reorder` and "
        "`predictive-reorder` against Draco's default (reordering) mode.",
        "",
        *markdown_table(
            equal_error_rows(rows),
            ("split", "model", "peer", "hausdorff", "peer_bpv", "ours", "ours_bpv", "ratio"),
        ),
        "",
        "### Size at Draco's RMS error",
        "",
        "As above at equal `rms_surface`: the root mean square of the exact vertex-to-surface "
        "distances both ways (defined with and without a vertex correspondence).",
        "",
        *markdown_table(
            equal_error_rows(rows, "rms_surface"),
            ("split", "model", "peer", "rms_surface", "peer_bpv", "ours", "ours_bpv", "ratio"),
        ),
        "",
        "### Feature-aware against uniform high-pass quantisation (equal rate)",
        "",
        "Algorithm 9 (`feature`) and the feature-unaware baseline (`uniform-delta`: every delta "
        "coordinate quantised with the same step, 1 % anchors) asked for the same whole-file "
        "rate (`conn+g`: the connectivity's bits per vertex plus `g`); both meet it within 5 %. "
        "`sent_share`: the share of the vertices whose deltas the rate control chose to send "
        "(most salient first; the others are set to zero, Eq. 5.53); 1 is uniform quantisation, "
        "so the two files are then the same. `feature_better`: on which of symmetric Hausdorff "
        "and theta the feature-aware file is better.",
        "",
        *markdown_table(
            feature_rows(rows),
            (
                "split",
                "model",
                "rate",
                "feature_bpv",
                "uniform_bpv",
                "sent_share",
                "feature_hausdorff",
                "uniform_hausdorff",
                "feature_theta",
                "uniform_theta",
                "feature_better",
            ),
        ),
        "",
        "### Every rate point",
        "",
        *markdown_table(rows, ("split", *cols)),
    ]
    return "\n".join(lines)
