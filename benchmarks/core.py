"""Foundation benchmarks: reading the 437k-vertex dragon and building its Laplacians; kNN graph of
2 million points. Each measurement runs in a fresh process so its peak memory is its own.

    python benchmarks/core.py            # writes benchmarks/_out/core.md
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, run_isolated, write_section  # noqa: E402
from spectrageo.datasets import data_dir  # noqa: E402

READ = """
import time
from spectrageo.io import read_mesh
t = time.perf_counter(); m = read_mesh({path!r}); dt = time.perf_counter() - t
RESULT = {{"n": m.n_vertices, "m": m.n_faces, "time_s": dt}}
"""

LAPLACIAN = """
import time
from spectrageo.io import read_mesh
from spectrageo.graph import mesh_laplacian
m = read_mesh({path!r})
t = time.perf_counter(); L = mesh_laplacian(m.vertices, m.faces, kind={kind!r}); dt = time.perf_counter() - t
RESULT = {{"nnz": int(L.nnz), "time_s": dt}}
"""

KNN = """
import time
import numpy as np
from spectrageo.graph import knn_graph
rng = np.random.default_rng(0)
u, v = rng.random({n}) * 2 * np.pi, rng.random({n}) * np.pi
P = np.c_[np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)] + 1e-3 * rng.normal(size=({n}, 3))
t = time.perf_counter(); W = knn_graph(P, {k}); dt = time.perf_counter() - t
RESULT = {{"nnz": int(W.nnz), "time_s": dt}}
"""


def main() -> None:
    data = data_dir(required=True)
    dragon = str(data / "meshes" / "dragon_vrip.ply.gz")
    rows = []
    r = run_isolated(READ.format(path=dragon))
    rows.append(
        ("read dragon_vrip.ply.gz", f"{r['n']:,} v / {r['m']:,} f", r["time_s"], r["peak_rss_mb"])
    )
    for kind in ("binary", "cotangent"):
        r = run_isolated(LAPLACIAN.format(path=dragon, kind=kind))
        rows.append(
            (
                f"{kind} Laplacian of the dragon",
                f"nnz {r['nnz']:,}",
                r["time_s"],
                r["peak_rss_mb"],
            )
        )
    n, k = 2_000_000, 10
    r = run_isolated(KNN.format(n=n, k=k))
    rows.append(
        (
            f"kNN graph, {n:,} points, k = {k} (symmetrised)",
            f"nnz {r['nnz']:,}",
            r["time_s"],
            r["peak_rss_mb"],
        )
    )
    lines = [
        "## Foundation: I/O, Laplacians, kNN graph",
        "",
        f"Machine: {machine_line()}. Regenerate with `python benchmarks/core.py`.",
        "Time is the operation alone (not the read); peak memory is the whole process (read included).",
        "",
        "| operation | size | time (s) | peak RSS (MB) |",
        "|---|---|---|---|",
    ]
    lines += [f"| {a} | {b} | {c:.2f} | {d:.0f} |" for a, b, c, d in rows]
    write_section("core", "\n".join(lines))


if __name__ == "__main__":
    main()
