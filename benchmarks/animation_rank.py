"""What issue 17's rate target asks of any eigen-trajectory coder: for every shared animation, the
rank an exact (unquantised) principal component analysis of the frames needs to reach the KG
error of Draco per frame at 12 bits, the real values such a representation holds per vertex and
frame, the cost of the order-kept connectivity spread over the frames, and the bits per value
left if the whole file is to stay at 1.0 bpvf.

    python benchmarks/animation_rank.py [--data DIR] [--out FILE.md]    # about 1 minute

The principal components are those of Section 5.2.2 (Eq. 5.46-5.48) taken on the vertex
coordinates of every frame (3n x T matrix, mean trajectory removed), truncated at the smallest
rank whose reconstruction meets Draco-12's KG error; no quantisation, so every coded method of
that family (``pca``, ``pca-q``, ``pca-qs``, ``pca-qp``, ``blocks``) needs at least that many
values, each with enough precision to keep the error. The values count the kept coefficients
(3n per component), the eigen-trajectories (T per component) and the mean (3n). Draco's KG error
is measured as in ``spectrageo evaluate compress-animation`` (nearest-vertex matching after
Draco's reordering, a lower bound).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, write_section  # noqa: E402
from spectrageo.compress._connectivity import encode_faces  # noqa: E402
from spectrageo.datasets.splits import cases  # noqa: E402
from spectrageo.evaluate.compress_animation import _draco  # noqa: E402
from spectrageo.io import read_animation  # noqa: E402
from spectrageo.metrics import kg_error  # noqa: E402

TARGET_BPVF = 1.0


def _rank_for(A: np.ndarray, target: float) -> int:
    """Smallest rank of the frames' principal components whose reconstruction has KG <= target."""
    T, n, _ = A.shape
    M = A.transpose(1, 2, 0).reshape(3 * n, T)
    mu = M.mean(axis=1, keepdims=True)
    U, s, Wt = np.linalg.svd(M - mu, full_matrices=False)
    lo, hi = 0, len(s)  # KG falls with the rank: bisect on it
    while lo < hi:
        mid = (lo + hi) // 2
        R = mu + (U[:, :mid] * s[:mid]) @ Wt[:mid]
        if kg_error(R.reshape(n, 3, T).transpose(2, 0, 1), A) <= target:
            hi = mid
        else:
            lo = mid + 1
    return lo


def row(rel: str, A: np.ndarray, F: np.ndarray, split: str) -> dict:
    T, n, _ = A.shape
    nb, R, _te, _td, _kept = _draco(A, F, 12, False)
    kg12 = float(kg_error(R, A))
    r = _rank_for(A, kg12)
    values = (3 * n * r + T * r + 3 * n) / (n * T)
    # the order-kept connectivity chunk every .sga file holds (``connectivity_bpvf`` of
    # ``compress.info_animation``)
    conn = 8.0 * len(encode_faces(F)) / (n * T)
    left = TARGET_BPVF - conn
    return {
        "model": Path(rel).stem,
        "split": split,
        "frames": T,
        "vertices": n,
        "draco12_kg": kg12,
        "draco12_bpvf": 8 * nb / (n * T),
        "rank": r,
        "values": values,
        "conn_bpvf": conn,
        "bits_per_value": left / values if left > 0 else float("nan"),
    }


def markdown(rows: list[dict]) -> str:
    lines = [
        "## What 1.0 bpvf at Draco-12's error asks of eigen-trajectory coding (issue 17)",
        "",
        f"`python benchmarks/animation_rank.py`. Machine: {machine_line()}.",
        "",
        "`rank`: the smallest number of principal components (Section 5.2.2, exact, not "
        "quantised) whose reconstruction reaches the KG error of Draco per frame at 12 bits; "
        "`values`: real numbers per vertex and frame such a representation holds (coefficients, "
        "eigen-trajectories, mean); `conn_bpvf`: the order-kept connectivity of a .sga file "
        "spread over the frames; `bits/value`: what a 1.0 bpvf file would leave for each value "
        "after the connectivity (`-`: the connectivity alone exceeds 1.0 bpvf).",
        "",
        "| split | model | frames | vertices | draco12_kg (%) | draco12_bpvf | rank | values | "
        "conn_bpvf | bits/value at 1.0 bpvf |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        b = r["bits_per_value"]
        lines.append(
            f"| {r['split']} | {r['model']} | {r['frames']} | {r['vertices']} | "
            f"{r['draco12_kg']:.4f} | {r['draco12_bpvf']:.1f} | {r['rank']} | "
            f"{r['values']:.2f} | {r['conn_bpvf']:.2f} | "
            f"{'-' if not np.isfinite(b) else f'{b:.2f}'} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("SPECTRAGEO_DATA", "../shared/data"))
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    rows = []
    for case in cases("compress-animation"):  # the split registry's cases, tuning first
        anim = read_animation(Path(args.data) / case.file)
        A = np.asarray(anim.frames, dtype=np.float64)
        F = np.asarray(anim.faces, dtype=np.int64)
        rows.append(row(case.file, A, F, case.split))
        print(rows[-1], file=sys.stderr, flush=True)
    md = markdown(rows)
    if args.out:
        tmp = Path(args.out).with_suffix(".tmp")
        tmp.write_text(md)
        os.replace(tmp, args.out)
    else:
        write_section("animation_rank", md)
    print(md)


if __name__ == "__main__":
    main()
