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
with ``PYTHONPATH=<checkout>/src`` (the section names the package path it imported), or compare
two builds in one run with ``--baseline <dir holding spectrageo/>``: per size, fresh processes
of this build and of the baseline take turns (``--rounds`` each, order swapped every round), each
timing both methods alternately (best of ``--repeat``) and hashing the removed set, so the
section reports both builds' ratios to Open3D and whether their removed sets are identical.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
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


CHILD = """
import json, sys, time, hashlib
sys.path.insert(0, {bench!r})
import numpy as np
import spectrageo
from bench_outliers_speed import _open3d, _rpca, make_cloud
z = np.load({path!r})
P = z["P"]
warm = make_cloud(20_000, seed=1)[0]
_rpca(warm)
_open3d(warm)
t_r, t_o, c_r = [], [], []
for _ in range({repeat}):
    t, c = time.perf_counter(), time.process_time()
    removed, _ = _rpca(P)
    t_r.append(time.perf_counter() - t)
    c_r.append(time.process_time() - c)
    t = time.perf_counter()
    _open3d(P)
    t_o.append(time.perf_counter() - t)
digest = hashlib.sha1(np.packbits(removed).tobytes()).hexdigest()
print(json.dumps({{"rpca_s": min(t_r), "o3d_s": min(t_o), "rpca_cpu_s": min(c_r),
                  "removed": digest, "n_removed": int(removed.sum()),
                  "package": spectrageo.__file__}}))
"""


def baseline_run(sizes, repeat: int, rounds: int, baseline: str) -> list[dict]:
    """This build and the one under ``baseline`` in alternating fresh processes, per size."""
    here = str(Path(__file__).resolve().parent)
    builds = {
        "current": str(Path(here).parent / "src"),
        "baseline": str(Path(baseline).resolve()),
    }
    rows = []
    for n in sizes:
        P, _ = make_cloud(n)
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "cloud.npz")
            np.savez(path, P=P)
            code = CHILD.format(bench=here, path=path, repeat=repeat)
            runs: dict[str, list[dict]] = {"current": [], "baseline": []}
            for r in range(rounds):
                for name in ("current", "baseline")[:: 1 if r % 2 == 0 else -1]:
                    env = {**os.environ, "PYTHONPATH": builds[name], "SPECTRAGEO_PROGRESS": "0"}
                    out = subprocess.run(
                        [sys.executable, "-c", code], capture_output=True, text=True, env=env
                    )
                    if out.returncode != 0:
                        raise RuntimeError(f"benchmark child failed:\n{out.stderr[-4000:]}")
                    runs[name].append(json.loads(out.stdout.strip().splitlines()[-1]))
                    print(name, n, runs[name][-1], os.getloadavg(), flush=True)
        row = {"n": P.shape[0]}
        for name, rs in runs.items():
            row[name] = {
                "rpca_s": min(x["rpca_s"] for x in rs),
                "rpca_cpu_s": min(x["rpca_cpu_s"] for x in rs),
                "o3d_s": min(x["o3d_s"] for x in rs),
                "ratio": max(x["o3d_s"] / x["rpca_s"] for x in rs),
                "ratios": [round(x["o3d_s"] / x["rpca_s"], 3) for x in rs],
                "package": rs[0]["package"],
            }
        digests = {x["removed"] for rs in runs.values() for x in rs}
        row["identical"] = len(digests) == 1
        row["n_removed"] = runs["current"][0]["n_removed"]
        rows.append(row)
    return rows


def _baseline_lines(rows: list[dict], args) -> list[str]:
    lines = [
        "",
        f"Against a baseline build (`--baseline {args.baseline}`): fresh processes of each build "
        f"in turn, {args.rounds} per build, each best of {args.repeat} (rpca and Open3D SOR "
        "(20, 2) alternately); load average at the end "
        + ", ".join(f"{x:.2f}" for x in os.getloadavg())
        + ". Ratio = Open3D time / rpca time in the same process (best process; all listed). "
        "rpca CPU: its CPU time over all threads (best run), the figure that depends least on "
        "the machine's load.",
        "",
        "| points | build | rpca (s) | rpca CPU (s) | Open3D SOR (s) | rpca / Open3D throughput "
        "| per process | removed sets identical |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for name in ("baseline", "current"):
            b = r[name]
            lines.append(
                f"| {r['n']:,} | {name} | {b['rpca_s']:.3f} | {b['rpca_cpu_s']:.3f} | "
                f"{b['o3d_s']:.3f} | "
                f"{b['ratio']:.2f} | {', '.join(f'{x:.2f}' for x in b['ratios'])} | "
                f"{'yes' if r['identical'] else 'NO'} ({r['n_removed']:,} removed) |"
            )
    return lines


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=lambda s: [int(x) for x in s.split(",") if x], default=SIZES)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--large", type=int, nargs="?", const=10_000_000, default=0)
    ap.add_argument("--baseline", default=None, help="directory holding another spectrageo/")
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()

    if args.baseline:
        rows = baseline_run(args.sizes, args.repeat, args.rounds, args.baseline)
        head = ["## Outlier removal throughput: this build vs a baseline, both vs Open3D SOR"]
        head += ["", f"Machine: {machine_line()}. Clouds as `same_run`."]
        write_section(
            "bench_outliers_speed_baseline", "\n".join(head + _baseline_lines(rows, args))
        )
        return
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
