"""Evaluation of rigid registration (thesis Sections 6.2.2-6.2.5): ``spectrageo evaluate register``.

Data: the Stanford bunny range-scan pairs with ground-truth overlap above 0.3 (``bun.conf``),
split by pair (``BUNNY_PAIRS`` of the registry); the real RGB-D fragment pair ``cloud_bin_0`` ->
``cloud_bin_1`` (identity ground truth: aligned as shipped); pairs of overlapping crops of the
real RGB-D fragment ``fragment.pcd``; and generated pairs, a shared mesh sampled twice (20,000
points), each cropped to a partial view keeping 65-85 % and given 0.2 % Gaussian noise. Every
source is moved by a random rigid motion of the split's seed.

Methods: ``spectrageo`` (:func:`spectrageo.register.register`) and, with :mod:`open3d`,
``o3d_ransac_fpfh_icp`` (its global-registration tutorial's parameters, seed fixed), ``o3d_fgr``
and ``o3d_icp``. Errors: rotation (Eq. 4.34, degrees) and translation over the target's diagonal
(Eq. 4.35); success below 5 degrees and 5 %; the 3DMatch registration recall below 15 degrees
and 10 % of the diagonal (its 30 cm on ~3 m fragments); wall time per pair in one process.

Splits (:mod:`spectrageo.datasets.splits`): defaults are chosen on :data:`TUNING` (seed 1, the
tuning bunny pairs, two fragment crops, armadillo); the tables report :data:`VALIDATION` (seed 0,
the other bunny pairs, four crops, five other meshes); the fragment pair is in both with other
motions (docs/decisions.md#register-defaults).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from ..datasets.splits import cases as _cases
from ._tables import have, markdown_table, pyplot, rows_to_csv, save_png, write_section


def _config(split: str) -> dict:
    """The seeds, bunny pairs and generated meshes of one split of the registry's ``register``
    task."""
    from ..datasets._split_register import BUNNY_PAIRS

    cs = _cases("register", split)
    scan = next(c for c in cs if c.name == "bunny")
    gen = [c for c in cs if c.file is not None and c.file.startswith("meshes/")]
    crops = next(c for c in cs if c.name == "fragment-crops")
    return {"bunny_seed": scan.seed, "reg_seed": scan.seed, "bunny_pairs": BUNNY_PAIRS[split],
            "n_crops": int(crops.corruption.split()[0]),
            "generated": tuple(c.name for c in gen), "gen_seed": gen[0].seed}  # fmt: skip


#: the splits of the split registry (:mod:`spectrageo.datasets.splits`, task ``register``)
TUNING = _config("tuning")
VALIDATION = _config("validation")
METHODS = ("spectrageo", "o3d_ransac_fpfh_icp", "o3d_fgr", "o3d_icp")
OVERLAP_BINS = ((0.3, 0.5), (0.5, 0.7), (0.7, 1.01))
MIN_OVERLAP = 0.3
ROT_TOL_DEG = 5.0
TRANS_TOL = 0.05
#: registration recall of the 3DMatch benchmark: rotation < 15 degrees and translation < 30 cm
#: on its ~3 m fragments, here 10 % of the target's bounding-box diagonal (29 cm on the fragment)
RECALL_ROT_DEG = 15.0
RECALL_TRANS = 0.1
GEN_PAIRS_PER_MESH = 2
GEN_POINTS = 20000
COLUMNS = ("data", "pair", "overlap", "method", "rot_err_deg", "trans_err", "success", "recall",
           "fitness", "converged", "seconds", "note", "split")  # fmt: skip


def _quat_matrix(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    x, y, z, w = qx, qy, qz, qw
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def bunny_scans(data: Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """``(name, points, T_world)`` of the bunny scans in ``bun.conf`` order; ``T_world`` maps the
    scan into the common frame (column convention; ``bun.conf``: ``P_world = P @ R(q) + t``)."""
    from .. import io
    from ..register._common import make_transform

    folder = data / "scans" / "bunny"
    out = []
    for line in (folder / "bun.conf").read_text().splitlines():
        p = line.split()
        if len(p) == 9 and p[0] == "bmesh":
            v = [float(x) for x in p[2:]]
            name = p[1].removesuffix(".ply")
            f = folder / f"{name}.ply.gz"
            if f.is_file():
                T = make_transform(_quat_matrix(*v[3:]).T, np.array(v[:3]))
                out.append((name, io.read_point_cloud(f).points, T))
    return out


def overlap(A: np.ndarray, B: np.ndarray) -> float:
    """Ground-truth overlap of two aligned clouds: the smaller of the two fractions of points (on a
    1/100-diagonal voxel grid) with a point of the other cloud within 1 % of the diagonal.
    """
    from scipy.spatial import cKDTree

    from ..register._common import bbox_diagonal, voxel_downsample

    diag = max(bbox_diagonal(A), bbox_diagonal(B))
    a, _ = voxel_downsample(A, diag / 100)
    b, _ = voxel_downsample(B, diag / 100)
    fa = float((cKDTree(B).query(a, distance_upper_bound=0.01 * diag)[0] < np.inf).mean())
    fb = float((cKDTree(A).query(b, distance_upper_bound=0.01 * diag)[0] < np.inf).mean())
    return min(fa, fb)


def _motion(rng: np.random.Generator, diag: float) -> np.ndarray:
    from ..register._common import make_transform, random_rotation

    t = rng.normal(size=3)
    t *= rng.uniform(0, 0.5 * diag) / max(np.linalg.norm(t), 1e-12)
    return make_transform(random_rotation(rng), t)


def bunny_pairs(data: Path, seed: int, names=None) -> list[dict]:
    """Pairs ``{data, pair, source, target, T_gt, overlap}`` with overlap > 0.3 (only ``names``
    when given); the source is moved by a random motion drawn from ``seed`` (``T_gt`` maps the
    moved source onto the target)."""
    from ..register._common import apply_transform

    scans = bunny_scans(data)
    rng = np.random.default_rng(seed)
    pairs = []
    world = [apply_transform(T, P) for _, P, T in scans]
    for i in range(len(scans)):
        for j in range(i + 1, len(scans)):
            ov = overlap(world[i], world[j])
            if ov <= MIN_OVERLAP:
                continue
            (ni, Pi, Ti), (nj, Pj, Tj) = scans[i], scans[j]
            M = _motion(rng, float(np.linalg.norm(np.ptp(Pj, axis=0))))
            T_gt = np.linalg.inv(Tj) @ Ti @ np.linalg.inv(M)
            pairs.append({"data": "bunny", "pair": f"{ni}->{nj}", "source": apply_transform(M, Pi),
                          "target": Pj, "T_gt": T_gt, "overlap": ov})  # fmt: skip
    return [p for p in pairs if names is None or p["pair"] in names]


def fragment_pairs(data: Path, seed: int) -> list[dict]:
    from .. import io
    from ..register._common import apply_transform

    folder = data / "scans" / "registration" / "open3d"
    a, b = folder / "cloud_bin_0.pcd", folder / "cloud_bin_1.pcd"
    if not (a.is_file() and b.is_file()):
        return []
    A, B = io.read_point_cloud(a).points, io.read_point_cloud(b).points
    M = _motion(np.random.default_rng(seed + 1000), float(np.linalg.norm(np.ptp(B, axis=0))))
    return [{"data": "open3d", "pair": "cloud_bin_0->cloud_bin_1", "source": apply_transform(M, A),
             "target": B, "T_gt": np.linalg.inv(M), "overlap": overlap(A, B)}]  # fmt: skip


def crop_pairs(data: Path, seed: int, n: int) -> list[dict]:
    """``n`` pairs of overlapping crops (each keeps 65-85 % of the points on one side of a random
    plane) of the real RGB-D fragment ``fragment.pcd``; the source moved by a random motion."""
    from .. import io
    from ..register._common import apply_transform, bbox_diagonal

    f = data / "scans" / "registration" / "open3d" / "fragment.pcd"
    if not f.is_file():
        return []
    P = io.read_point_cloud(f).points
    P = P[np.isfinite(P).all(axis=1)]
    rng = np.random.default_rng(seed + 3000)
    pairs = []
    for k in range(n):
        A, B = _crop(P, rng), _crop(P, rng)
        M = _motion(rng, bbox_diagonal(B))
        pairs.append({"data": "fragment-crops", "pair": f"fragment#{k}", "source": apply_transform(M, A),
                      "target": B, "T_gt": np.linalg.inv(M), "overlap": overlap(A, B)})  # fmt: skip
    return pairs


def _sample_surface(V: np.ndarray, F: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    f = rng.choice(F.shape[0], size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return a[f] + u[:, None] * (b[f] - a[f]) + v[:, None] * (c[f] - a[f])


def _crop(P: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    s = P @ d
    return P[s <= np.quantile(s, rng.uniform(0.65, 0.85))]


def generated_pairs(data: Path, meshes, seed: int) -> list[dict]:
    """Two noisy partial samples of each mesh (see the module docstring)."""
    from .. import io
    from ..register._common import apply_transform, bbox_diagonal

    rng = np.random.default_rng(seed + 2000)
    pairs = []
    for name in meshes:
        f = data / "meshes" / f"{name}.off"
        if not f.is_file():
            continue
        m = io.read_mesh(f)
        diag = bbox_diagonal(m.vertices)
        for k in range(GEN_PAIRS_PER_MESH):
            A = _crop(_sample_surface(m.vertices, m.faces, GEN_POINTS, rng), rng)
            B = _crop(_sample_surface(m.vertices, m.faces, GEN_POINTS, rng), rng)
            A = A + rng.normal(scale=0.002 * diag, size=A.shape)
            B = B + rng.normal(scale=0.002 * diag, size=B.shape)
            M = _motion(rng, diag)
            pairs.append({"data": "generated", "pair": f"{name}#{k}", "source": apply_transform(M, A),
                          "target": B, "T_gt": np.linalg.inv(M), "overlap": overlap(A, B)})  # fmt: skip
    return pairs


# --------------------------------------------------------------------------- methods
def _ours(S: np.ndarray, T: np.ndarray, seed: int) -> tuple[np.ndarray, float, bool]:
    import warnings

    from ..register import register

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = register(S, T, rng=seed)
    return res.transformation, res.fitness, bool(res.converged)


def _o3d_prepare(P: np.ndarray, voxel: float):
    import open3d as o3d

    reg = o3d.pipelines.registration
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    down = pc.voxel_down_sample(voxel)
    down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    feat = reg.compute_fpfh_feature(
        down, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100)
    )
    return pc, down, feat


def _o3d_refine(src, tgt, T0: np.ndarray, dist: float) -> tuple[np.ndarray, float]:
    import open3d as o3d

    reg = o3d.pipelines.registration
    if not tgt.has_normals():
        tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=dist, max_nn=30))
    r = reg.registration_icp(src, tgt, dist, T0, reg.TransformationEstimationPointToPlane(),
                             reg.ICPConvergenceCriteria(max_iteration=60))  # fmt: skip
    return np.asarray(r.transformation), float(r.fitness)


def _o3d_method(method: str, S: np.ndarray, T: np.ndarray, seed: int) -> tuple[np.ndarray, float]:
    import open3d as o3d

    from ..register._common import bbox_diagonal

    reg = o3d.pipelines.registration
    if hasattr(o3d.utility, "random"):
        o3d.utility.random.seed(seed)
    diag = max(bbox_diagonal(S), bbox_diagonal(T))
    voxel = diag / 50
    if method == "o3d_icp":
        src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(S))
        tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(T))
        return _o3d_refine(src, tgt, np.eye(4), 0.05 * diag)
    src, sd, sf = _o3d_prepare(S, voxel)
    tgt, td, tf = _o3d_prepare(T, voxel)
    if method == "o3d_fgr":
        r = reg.registration_fgr_based_on_feature_matching(
            sd,
            td,
            sf,
            tf,
            reg.FastGlobalRegistrationOption(maximum_correspondence_distance=0.5 * voxel),
        )
        return np.asarray(r.transformation), float(r.fitness)
    dist = 1.5 * voxel
    r = reg.registration_ransac_based_on_feature_matching(
        sd, td, sf, tf, True, dist, reg.TransformationEstimationPointToPoint(False), 3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(dist)],
        reg.RANSACConvergenceCriteria(100000, 0.999),
    )  # fmt: skip
    return _o3d_refine(src, tgt, np.asarray(r.transformation), 0.4 * voxel)


def _run(method: str, pair: dict, seed: int) -> dict:
    from ..metrics import registration as rm
    from ..register._common import bbox_diagonal

    S, T, T_gt = pair["source"], pair["target"], pair["T_gt"]
    t0 = time.perf_counter()
    note = ""
    conv = None
    try:
        if method == "spectrageo":
            Th, fit, conv = _ours(S, T, seed)
        else:
            Th, fit = _o3d_method(method, S, T, seed)
    except Exception as exc:  # noqa: BLE001 - a failing peer is a failed run, recorded as such
        Th, fit, note = np.eye(4), float("nan"), f"error: {type(exc).__name__}"
    sec = time.perf_counter() - t0
    re = rm.rotation_error_deg(Th, T_gt)
    te = rm.translation_error(Th, T_gt) / bbox_diagonal(T)
    return {"data": pair["data"], "pair": pair["pair"], "overlap": pair["overlap"], "method": method,
            "rot_err_deg": re, "trans_err": te, "success": bool(re < ROT_TOL_DEG and te < TRANS_TOL),
            "recall": bool(re < RECALL_ROT_DEG and te < RECALL_TRANS), "fitness": fit,
            "converged": conv, "seconds": sec, "note": note}  # fmt: skip


def pairs_for(data: Path, split: dict, parts=("bunny", "open3d", "generated", "fragment-crops")
              ) -> list[dict]:  # fmt: skip
    out: list[dict] = []
    if "bunny" in parts:
        out += bunny_pairs(data, split["bunny_seed"], split.get("bunny_pairs"))
    if "open3d" in parts:
        out += fragment_pairs(data, split["bunny_seed"])
    if "generated" in parts:
        out += generated_pairs(data, split["generated"], split["gen_seed"])
    if "fragment-crops" in parts:
        out += crop_pairs(data, split["bunny_seed"], split["n_crops"])
    return out


def evaluate(
    data_dir: Any,
    methods: list[str] | None = None,
    out: Any = None,
    *,
    split: str = "validation",
    parts: tuple[str, ...] = ("bunny", "open3d", "fragment-crops", "generated"),
    max_pairs: int | None = None,
) -> list[dict]:
    """Run the registration benchmark; one row per (pair, method) with the keys of
    :data:`COLUMNS`. ``methods`` restricts :data:`METHODS` (Open3D peers are skipped when
    :mod:`open3d` is missing); ``split`` is ``"validation"`` (reported) or ``"tuning"`` (each
    row carries it; the registry's ``consulted_by`` says the validation scan pairs are the tuning
    ones moved by other motions);
    ``max_pairs`` keeps the first pairs of each part (for quick runs)."""
    data = Path(data_dir)
    if not data.is_dir():
        raise InvalidInputError(f"`data_dir` must be a folder; got {data}.")
    sel = list(methods) if methods else list(METHODS)
    unknown = set(sel) - set(METHODS)
    if unknown:
        raise InvalidInputError(
            f"unknown method(s) {', '.join(sorted(unknown))}; known: {', '.join(METHODS)}."
        )
    if split not in ("validation", "tuning"):
        raise InvalidInputError(f"`split` must be 'validation' or 'tuning'; got {split!r}.")
    if not have("open3d"):
        sel = [m for m in sel if not m.startswith("o3d")]
    cfg = VALIDATION if split == "validation" else TUNING
    rows: list[dict] = []
    for part in parts:
        pairs = pairs_for(data, cfg, (part,))
        if max_pairs is not None:
            pairs = pairs[:max_pairs]
        for pair in pairs:
            for m in sel:
                rows.append({**_run(m, pair, cfg["reg_seed"]), "split": split})
    if out is not None:
        write_tables(rows, out)
    return rows


def _bin(ov: float) -> str:
    for lo, hi in OVERLAP_BINS:
        if lo <= ov < hi:
            return f"{lo:.1f}-{min(hi, 1.0):.1f}"
    return f"<{OVERLAP_BINS[0][0]:.1f}"


def summary(rows: list[dict]) -> list[dict]:
    """Success rate, median errors and mean time per (data, overlap bin, method), plus 'all'."""
    out = []
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        for key in ((r["data"], _bin(r["overlap"]), r["method"]), ("all", "all", r["method"])):
            groups.setdefault(key, []).append(r)
    data_order = {"bunny": 0, "open3d": 1, "fragment-crops": 2, "generated": 3, "all": 4}
    meth_order = {m: i for i, m in enumerate(METHODS)}

    def order(key: tuple) -> tuple:
        d, b, m = key
        return (data_order.get(d, 9), b, meth_order.get(m, 9), m)

    for (d, b, m), rr in sorted(groups.items(), key=lambda kv: order(kv[0])):
        out.append({"data": d, "bin": b, "method": m, "n": len(rr),
                    "success": sum(x["success"] for x in rr),
                    "rate": float(np.mean([x["success"] for x in rr])),
                    "recall": float(np.mean([x.get("recall", x["success"]) for x in rr])),
                    "med_rot_err_deg": float(np.median([x["rot_err_deg"] for x in rr])),
                    "p90_rot_err_deg": float(np.percentile([x["rot_err_deg"] for x in rr], 90)),
                    "med_trans_err": float(np.median([x["trans_err"] for x in rr])),
                    "p90_trans_err": float(np.percentile([x["trans_err"] for x in rr], 90)),
                    "mean_seconds": float(np.mean([x["seconds"] for x in rr])),
                    "med_seconds": float(np.median([x["seconds"] for x in rr]))})  # fmt: skip
    return out


def format_markdown(rows: list[dict]) -> str:
    """Summary table (success per data set / overlap bin / method) followed by the per-pair rows."""
    cols = ("data", "bin", "method", "n", "success", "rate", "recall", "med_rot_err_deg",
            "p90_rot_err_deg", "med_trans_err", "p90_trans_err", "mean_seconds",
            "med_seconds")  # fmt: skip
    return "\n".join([*markdown_table(summary(rows), cols), "", *markdown_table(rows, COLUMNS)])


def format_csv(rows: list[dict]) -> str:
    return rows_to_csv(rows, COLUMNS)


def write_tables(rows: list[dict], out) -> tuple[Path, Path]:
    """Write ``<out>.md``, ``<out>.csv`` and (with matplotlib) ``<out>.png``."""
    md, cs = write_section(
        out,
        "Registration (Section 6.2)",
        "Produced by `spectrageo evaluate register` (validation split). Success = rotation error "
        "< 5 deg and translation error < 5 % of the target's bounding-box diagonal; recall = the "
        "3DMatch registration recall, rotation < 15 deg and translation < 10 % of that diagonal "
        "(its 30 cm on ~3 m fragments); `trans_err` is relative to that diagonal; bins are "
        "ground-truth overlap; times are per pair in one process.",
        format_markdown(rows),
        format_csv(rows),
    )
    _plot(rows, md.with_suffix(".png"))
    return md, cs


def _plot(rows: list[dict], png: Path) -> Path | None:
    """Success rate against the overlap bin, one curve per method."""
    if not rows or not have("matplotlib"):
        return None
    plt = pyplot()

    bins = [f"{lo:.1f}-{min(hi, 1.0):.1f}" for lo, hi in OVERLAP_BINS]
    fig, ax = plt.subplots(figsize=(6, 4))
    for m in dict.fromkeys(r["method"] for r in rows):
        ys = []
        for b in bins:
            rr = [r["success"] for r in rows if r["method"] == m and _bin(r["overlap"]) == b]
            ys.append(np.mean(rr) if rr else np.nan)
        ax.plot(bins, ys, marker="o", label=m)
    ax.set_xlabel("ground-truth overlap")
    ax.set_ylabel("success rate (5 deg, 5 % diag)")
    ax.set_ylim(-0.05, 1.05)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return save_png(fig, png)


__all__ = ["COLUMNS", "METHODS", "TUNING", "VALIDATION", "evaluate", "format_csv",
           "format_markdown", "summary", "write_tables"]  # fmt: skip
