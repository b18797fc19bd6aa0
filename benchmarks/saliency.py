"""Saliency benchmarks (thesis Section 6.1.2, Table 6.1, Figs. 6.16-6.17).

* correlation with the reference per-face maps of block, cad, casting and fandisk, timings of the
  original and the fast variant, invariance and stability (``spectrageo evaluate saliency``);
* time of a saliency map of a ~100k-face mesh (the dragon_vrip_res2 scan decimated to half its
  vertices), each variant in a fresh process.

    python benchmarks/saliency.py        # writes benchmarks/_out/saliency.md (+ saliency.csv)
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import OUT, machine_line, run_isolated, write_section  # noqa: E402
from spectrageo.datasets import data_dir  # noqa: E402

LARGE = """
import time
import numpy as np
from spectrageo.io import read_mesh
from spectrageo.saliency import SaliencyOptions, saliency, simplify
m = read_mesh({path!r})
d = simplify(m.vertices, m.faces, ratio=0.5, saliency=np.zeros(m.n_vertices), n_classes=1, rng=0)
V, F = d.vertices, d.faces
saliency(V[:2000], F[np.all(F < 2000, axis=1)], method={method!r})  # warm the jitted kernels
best, cpu = np.inf, np.inf
for _ in range(2):
    t, c = time.perf_counter(), time.process_time()
    s = saliency(V, F, SaliencyOptions(fast={fast!r}), method={method!r})
    best, cpu = min(best, time.perf_counter() - t), min(cpu, time.process_time() - c)
RESULT = {{"n": int(len(V)), "m": int(len(F)), "time_s": best, "cpu_s": cpu}}
"""


def main() -> None:
    from spectrageo.evaluate.saliency import evaluate, format_markdown

    data = data_dir(required=True)
    rows = evaluate(data, out=OUT / "saliency", repeat=3)
    lines = [
        "## Saliency maps (Section 6.1.2)",
        "",
        f"Machine: {machine_line()}.",
        "",
        "Per-face maps against the reference maps in `saliency/` (Pearson / Spearman), the time "
        "of one map (best of 3, wall clock and process CPU time, guided normals and patches "
        "included), the fast "
        "variant against the original (Table 6.1), and the Pearson correlation of per-vertex "
        "maps with those of a rotated + scaled (x3.7) + translated copy, a copy with 30 % of the "
        "vertices removed (compared at the remaining vertices) and a copy with Gaussian noise "
        "0.1 x mean edge length. Command: `spectrageo evaluate saliency --out "
        "benchmarks/_out/saliency`.",
        "",
        format_markdown(rows),
        "",
        "### Large mesh",
        "",
        "| mesh | method | vertices | faces | wall (s) | CPU (s) | peak RSS (MB) |",
        "|---|---|---|---|---|---|---|",
    ]
    path = str(data / "meshes" / "dragon_vrip_res2.ply.gz")
    for method, fast in (("combined", False), ("combined", True), ("spectral", False)):
        r = run_isolated(LARGE.format(path=path, method=method, fast=fast))
        label = method + (" (fast)" if fast else "")
        lines.append(
            f"| dragon_vrip_res2, half the vertices | {label} | {r['n']:,} | {r['m']:,} | "
            f"{r['time_s']:.2f} | {r['cpu_s']:.2f} | {r['peak_rss_mb']:.0f} |"
        )
    md = "\n".join(lines)
    print(md)
    write_section("saliency", md)


if __name__ == "__main__":
    main()
