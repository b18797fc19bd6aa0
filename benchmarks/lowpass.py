"""Partitioned spectral low-pass (Eq. 5.45) with exact, OI and DOI submesh bases, against the
whole-mesh sparse eigensolver, on the bunny (35k v), dragon res2 (100k v) and full dragon (437k v).

    python benchmarks/lowpass.py            # writes benchmarks/_out/lowpass.md

Every mesh runs in a fresh process. Per-submesh methods keep 10 % of the components of every
700-vertex submesh (overlap 15 %, binary Laplacian, OI: one iteration of T^4). The reported time
is the eigenbases + projections + reassembly (the METIS partition, shared by all three, is listed
separately; the compiled kernels are loaded by a warm-up run first). The error is the mean vertex displacement of the low-passed mesh from the input,
in units of 1e-3 of the bounding-box diagonal (the quantity a low-pass is meant to keep small for
a given number of coefficients). The whole-mesh reference (``scipy.sparse.linalg.eigsh``,
shift-invert) cannot keep 10 % of ``n`` eigenvectors on these meshes (3.5k to 44k dense vectors):
it is run with ``k = 100`` components, a different (much stronger) compression, to show its cost.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, run_isolated, write_section  # noqa: E402
from spectrageo.datasets import data_dir  # noqa: E402

MESHES = [
    ("bunny", "meshes/stanford-bunny.obj"),
    ("dragon res2", "meshes/dragon_vrip_res2.ply.gz"),
    ("dragon (full)", "meshes/dragon_vrip.ply.gz"),
]
WHOLE_K = 100
WHOLE_MAX_N = 150_000  # above this the whole-mesh eigsh is not attempted (see the note)

PARTITIONED = """
import time
import numpy as np
from spectrageo.io import read_mesh
from spectrageo.spectral import SubmeshOptions, overlapped_submeshes, reassemble, submesh_eigenbases
from spectrageo.spectral.lowpass import _binary_adjacency
m = read_mesh({path!r})
V, F = m.vertices, m.faces
n = V.shape[0]
diag = float(np.linalg.norm(np.ptp(V, axis=0)))
C = _binary_adjacency(F, n)
t = time.perf_counter(); subs = overlapped_submeshes(C, submesh_size=700, overlap=0.15, rng=0)
t_part = time.perf_counter() - t
out = {{"n": n, "n_sub": len(subs), "t_part": t_part}}
# warm-up: load the compiled (numba, cache=True) kernels once, outside the timings
head = type(subs)(subs.parts[:3], subs.cores[:3], subs.n_vertices, subs.degrees[:3])
for method in ("exact", "oi", "doi"):
    for _ in submesh_eigenbases(C, head, 0.1, method=method, signal=V, options=SubmeshOptions(ritz=False), rng=0):
        pass
res = {{}}
for method in ("exact", "oi", "doi"):
    t = time.perf_counter()
    vals = [None] * len(subs)
    sizes = []
    for i, _w, U in submesh_eigenbases(C, subs, 0.1, method=method, signal=V if method == "doi" else None,
                                       options=SubmeshOptions(ritz=False), rng=0):
        x = V[subs.parts[i]]
        vals[i] = U @ (U.T @ x)
        sizes.append(U.shape[1])
    Vl = reassemble(vals, subs)
    dt = time.perf_counter() - t
    err = float(np.linalg.norm(Vl - V, axis=1).mean()) / diag * 1e3
    res[method] = {{"time_s": dt, "err": err, "mean_k": float(np.mean(sizes))}}
out["res"] = res
RESULT = out
"""

WHOLE = """
import time
import numpy as np
from spectrageo.io import read_mesh
from spectrageo.graph import mesh_laplacian
from spectrageo.spectral import Eigenbasis
m = read_mesh({path!r})
V, F = m.vertices, m.faces
diag = float(np.linalg.norm(np.ptp(V, axis=0)))
L = mesh_laplacian(V, F, kind="binary")
t = time.perf_counter()
B = Eigenbasis.from_laplacian(L, {k}, method="sparse")
Vl = B.lowpass(V, {k})
dt = time.perf_counter() - t
RESULT = {{"time_s": dt, "err": float(np.linalg.norm(Vl - V, axis=1).mean()) / diag * 1e3}}
"""


def main() -> None:
    root = data_dir()
    if root is None:
        raise SystemExit("shared data not found (set SPECTRAGEO_DATA)")
    rows = []
    for name, rel in MESHES:
        path = str(root / rel)
        print(f"{name} ...", file=sys.stderr, flush=True)
        r = run_isolated(PARTITIONED.format(path=path), timeout=3600)
        whole = None
        if r["n"] <= WHOLE_MAX_N:
            try:
                whole = run_isolated(WHOLE.format(path=path, k=WHOLE_K), timeout=1200)
            except Exception as exc:  # noqa: BLE001 - reported in the table
                whole = {"error": type(exc).__name__}
        rows.append((name, r, whole))

    lines = [
        "## Partitioned spectral low-pass (Eq. 5.45): exact vs OI vs DOI per submesh",
        "",
        f"Machine: {machine_line()}. Command: `python benchmarks/lowpass.py`.",
        "",
        "Submeshes of 700 vertices (15 % overlap, METIS), 10 % of the components kept per submesh,",
        "binary Laplacian, OI = one iteration of T^4 warm-started from the previous submesh, DOI band",
        "[0.02, 0.03] of the relative residual. Time: eigenbases + projections + reassembly (the",
        "partition time is listed apart). Error: mean displacement from the input, 1e-3 x bbox",
        "diagonal. `k` = mean number of components per submesh.",
        "",
        "| mesh | n | submeshes | partition s | exact s | exact err | OI s | OI err | DOI s | DOI err (k) "
        "| speed-up exact/OI | OI err / exact err | whole eigsh k=100 s | whole err |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r, whole in rows:
        e, o, d = r["res"]["exact"], r["res"]["oi"], r["res"]["doi"]
        if whole is None:
            ws, we = f"not run (n > {WHOLE_MAX_N})", "-"
        elif "error" in whole:
            ws, we = f"failed ({whole['error']})", "-"
        else:
            ws, we = f"{whole['time_s']:.1f}", f"{whole['err']:.3f}"
        lines.append(
            f"| {name} | {r['n']} | {r['n_sub']} | {r['t_part']:.1f} | {e['time_s']:.1f} | "
            f"{e['err']:.3f} | {o['time_s']:.1f} | {o['err']:.3f} | {d['time_s']:.1f} | "
            f"{d['err']:.3f} ({d['mean_k']:.0f}) | {e['time_s'] / o['time_s']:.1f}x | "
            f"{o['err'] / e['err']:.2f} | {ws} | {we} |"
        )
    lines += [
        "",
        "Target of the issue: OI at least 10x faster than exact at an error within 20 %. The",
        "whole-mesh eigsh keeps only 100 components (keeping 10 % of n, as the submeshes do, would",
        "need 3.5k-44k eigenvectors); it is not attempted on the full dragon, where a shift-invert",
        "ARPACK run with a useful k does not fit the time budget of this shared machine.",
    ]
    write_section("lowpass", "\n".join(lines))


if __name__ == "__main__":
    main()
