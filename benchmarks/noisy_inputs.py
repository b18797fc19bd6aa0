"""Metrics of every shared noisy input against its ground truth (the "noisy input" rows of the
thesis's denoising tables, Section 4.9), computed with the same code as ``spectrageo metrics``.

    python benchmarks/noisy_inputs.py      # writes benchmarks/_out/noisy_inputs.md
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, write_section  # noqa: E402
from spectrageo import io, metrics  # noqa: E402
from spectrageo.datasets import data_dir, denoise_pairs  # noqa: E402


def main() -> None:
    root = data_dir(required=True)
    rows = []
    for name, noisy, orig in denoise_pairs(root):
        N, O = io.read_mesh(noisy), io.read_mesh(orig)
        t = time.perf_counter()
        d = metrics.compare(N, O, faces_result=N.faces)
        dt = time.perf_counter() - t
        rows.append((name, O.n_vertices, O.n_faces, d, dt))
    lines = [
        "## Noisy inputs against their ground truth",
        "",
        "`python benchmarks/noisy_inputs.py` (equivalently `spectrageo metrics Noisy.obj Original.obj "
        "--json` per pair in `denoise/` of the shared data). theta in degrees; Dmean d, Dmax d and "
        "the Hausdorff values (symmetric: vertices, edge midpoints and face centroids of each surface "
        "to the exact nearest point of the other; HD mean averages the two area-weighted means) in model "
        "units; dist n and Dmean n unitless; NMSVE normalised by the squared bounding-box diagonal.",
        f"Machine: {machine_line()}.",
        "",
        "| pair | vertices | faces | theta (deg) | Dmean d | Dmax d | dist n | Dmean n | NMSVE "
        "| HD mean | HD max | time (s) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, n, m, d, dt in rows:
        lines.append(
            f"| {name} | {n} | {m} | {d['theta_deg']:.3f} | {d['dmean']:.3e} | {d['dmax']:.3e} "
            f"| {d['dist_n']:.4f} | {d['dmean_n']:.4f} | {d['nmsve']:.3e} | {d['hd_mean']:.3e} "
            f"| {d['hd_max']:.3e} | {dt:.2f} |"
        )
    write_section("noisy_inputs", "\n".join(lines))


if __name__ == "__main__":
    main()
