"""Outlier removal throughput: default ``rpca`` vs Open3D's statistical outlier removal, same run.

Clouds of 100k, 500k and 2M points sampled uniformly (area-weighted) on the Stanford dragon
(``meshes/dragon_vrip.ply.gz`` of the shared data) with Gaussian noise of 0.2 mean point spacings
along the surface normal, plus 10 % outliers of the ``mixed`` pattern of
:func:`spectrageo.noise.corrupt_outliers` (half uniform in the padded bounding box, half a halo
5-15 spacings away: the case of the outlier issue). Per size, ``remove_outliers(method="rpca")``
at its defaults and Open3D's ``remove_statistical_outlier(nb_neighbors=20, std_ratio=2.0)`` run
alternately in one process (best of ``--repeat``), after one warm-up call of each; Open3D
also at ``nb_neighbors=10, std_ratio=1.0`` (the same ``k`` as ours, a cheaper search). Points per
second, their ratio and the F1 of the removed points are reported. ``--large N`` adds one run of
each method on ``N`` points (default 10^7) in a fresh process, with its peak resident memory
(the 10 % outliers and the input array included).

    python benchmarks/bench_outliers_speed.py                    # 100k, 500k, 2M
    python benchmarks/bench_outliers_speed.py --sizes 100000 --repeat 5
    python benchmarks/bench_outliers_speed.py --large 10000000   # also 10^7, time and memory

Writes ``benchmarks/_out/bench_outliers_speed.md``. Run it against another checkout of the package
with ``PYTHONPATH=<checkout>/src`` (the section names the package path it imported).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, run_isolated, write_section  # noqa: E402

SIZES = (100_000, 500_000, 2_000_000)


def make_cloud(n: int, *, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` inlier points on the dragon (noisy along the normal) + 10 % ``mixed`` outliers."""
    from spectrageo import io, noise
    from spectrageo.datasets import data_dir

    mesh = io.read(Path(data_dir(required=True)) / "meshes/dragon_vrip.ply.gz", kind="mesh")
    V, F = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    rng = np.random.default_rng(seed)
    e1, e2 = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    cr = np.cross(e1, e2)
    area = np.linalg.norm(cr, axis=1)
    f = rng.choice(F.shape[0], n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    P = V[F[f, 0]] + u[:, None] * e1[f] + v[:, None] * e2[f]
    nrm = cr[f] / np.maximum(area[f], 1e-300)[:, None]
    spacing = np.sqrt(area.sum() / n)  # mean spacing of n points on the surface
    P += (0.2 * spacing * rng.standard_normal(n))[:, None] * nrm
    return noise.corrupt_outliers(P, pattern="mixed", fraction=0.1, rng=seed)


def _f1(removed: np.ndarray, lab: np.ndarray) -> float:
    tp = int(np.count_nonzero(removed & lab))
    p = tp / max(int(np.count_nonzero(removed)), 1)
    r = tp / max(int(np.count_nonzero(lab)), 1)
    return 2 * p * r / (p + r) if p + r > 0 else 0.0


def _rpca(P: np.ndarray) -> tuple[np.ndarray, dict]:
    from spectrageo.outliers import detect_outliers

    r = detect_outliers(P, method="rpca")
    return ~r.keep, r.info


def _open3d(P: np.ndarray, nb_neighbors: int = 20, std_ratio: float = 2.0) -> np.ndarray:
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    _, ind = pc.remove_statistical_outlier(nb_neighbors=nb_neighbors, std_ratio=std_ratio)
    removed = np.ones(P.shape[0], dtype=bool)
    removed[np.asarray(ind, dtype=np.int64)] = False
    return removed


def same_run(sizes, repeat: int) -> list[dict]:
    """Both methods alternately on each size (best of ``repeat``)."""
    warm = make_cloud(20_000, seed=1)[0]
    _rpca(warm)
    _open3d(warm)
    rows = []
    for n in sizes:
        P, lab = make_cloud(n)
        t_r, t_o, t_o10 = [], [], []
        for _ in range(repeat):
            t = time.perf_counter()
            rem_r, info = _rpca(P)
            t_r.append(time.perf_counter() - t)
            t = time.perf_counter()
            rem_o = _open3d(P)
            t_o.append(time.perf_counter() - t)
            t = time.perf_counter()
            rem_o10 = _open3d(P, 10, 1.0)
            t_o10.append(time.perf_counter() - t)
        rows.append(
            {
                "n": P.shape[0],
                "rpca_s": min(t_r),
                "o3d_s": min(t_o),
                "o3d10_s": min(t_o10),
                "rpca_f1": _f1(rem_r, lab),
                "o3d_f1": _f1(rem_o, lab),
                "o3d10_f1": _f1(rem_o10, lab),
                "n_iter": info.get("n_iter"),
            }
        )
        print(rows[-1], flush=True)
    return rows


LARGE = """
import time, numpy as np
z = np.load({path!r})
P, lab = z["P"], z["lab"]
del z
t = time.perf_counter()
if {method!r} == "rpca":
    from spectrageo.outliers import detect_outliers
    detect_outliers(P[:2000], method="rpca")  # load the compiled kernels
    t = time.perf_counter()
    removed = ~detect_outliers(P, method="rpca").keep
else:
    import open3d as o3d
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    _, ind = pc.remove_statistical_outlier(nb_neighbors=20, std_ratio=2.0)
    removed = np.ones(P.shape[0], bool); removed[np.asarray(ind)] = False
dt = time.perf_counter() - t
tp = int((removed & lab).sum()); p = tp / max(int(removed.sum()), 1); r = tp / int(lab.sum())
RESULT = {{"time_s": dt, "f1": 2 * p * r / max(p + r, 1e-12)}}
"""


def large_run(n: int) -> list[tuple[str, dict]]:
    """One fresh process per method on ``n`` points: time and peak resident memory."""
    P, lab = make_cloud(n)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "cloud.npz")
        np.savez(path, P=P, lab=lab)
        del P, lab
        out = [("rpca", run_isolated(LARGE.format(path=path, method="rpca")))]
        out.append(("open3d-sor", run_isolated(LARGE.format(path=path, method="open3d"))))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=lambda s: [int(x) for x in s.split(",") if x], default=SIZES)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--large", type=int, nargs="?", const=10_000_000, default=0)
    args = ap.parse_args()

    rows = same_run(args.sizes, args.repeat) if args.sizes else []
    lines = [
        "## Outlier removal throughput: rpca vs Open3D SOR",
        "",
        f"Machine: {machine_line()}. Dragon "
        "surface samples + 10 % `mixed` outliers; `rpca` = `remove_outliers(method='rpca')` "
        "defaults (k = 10), Open3D = `remove_statistical_outlier(nb_neighbors=20, "
        "std_ratio=2.0)` (the usual setting) and, last three columns, with `nb_neighbors=10, "
        "std_ratio=1.0` (our k; std_ratio 1.0 is our `sor` default), "
        f"alternately in one process, best of {args.repeat}. Reproduce: "
        "`python benchmarks/bench_outliers_speed.py`.",
        "",
        "| points | rpca (s) | rpca points/s | Open3D SOR (s) | Open3D points/s | "
        "rpca / Open3D throughput | rpca F1 | Open3D F1 | Open3D k=10 (s) | "
        "rpca / Open3D k=10 throughput | Open3D k=10 F1 |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['n']:,} | {r['rpca_s']:.3f} | {r['n'] / r['rpca_s']:,.0f} | {r['o3d_s']:.3f} | "
            f"{r['n'] / r['o3d_s']:,.0f} | {r['o3d_s'] / r['rpca_s']:.2f} | {r['rpca_f1']:.3f} | "
            f"{r['o3d_f1']:.3f} | {r['o3d10_s']:.3f} | {r['o3d10_s'] / r['rpca_s']:.2f} | "
            f"{r['o3d10_f1']:.3f} |"
        )
    if args.large:
        lines += [
            "",
            f"{args.large:,} points (+10 %), one fresh process per method; peak memory is the "
            "process's maximum resident set size, input included:",
            "",
            "| method | time (s) | points/s | peak memory (MB) | F1 |",
            "|---|---|---|---|---|",
        ]
        for name, r in large_run(args.large):
            n = int(round(args.large * 1.1))
            lines.append(
                f"| {name} | {r['time_s']:.1f} | {n / r['time_s']:,.0f} | "
                f"{r['peak_rss_mb']:,.0f} | {r['f1']:.3f} |"
            )
    write_section("bench_outliers_speed", "\n".join(lines))


if __name__ == "__main__":
    main()
