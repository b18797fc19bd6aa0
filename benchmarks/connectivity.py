"""Order-preserving connectivity coding of the .sgc/.sga containers on every shared mesh.

    python benchmarks/connectivity.py      # writes benchmarks/_out/connectivity.md

Columns (bits per vertex): ``delta`` is the previous code (zstd of index differences), ``kept`` is
what a file now holds (the smaller of the traversal and delta codes, order kept), ``bound`` is
``log2(m!) + log2(n!)`` / n, the cost of the two orders alone when they are random (files whose
orders follow a traversal can go below it); ``rcm`` is the previous ``--reorder`` (reverse
Cuthill-McKee vertices, sorted faces, delta code), ``reorder`` the option now (the traversal's
own order, or the input's where that codes smaller);
``draco1`` is Draco's whole file at 1 quantisation bit (its connectivity plus a near-empty
geometry stream; Draco reorders). Split: the coder was designed while looking at the tuning
meshes (``meshes/``, ``cad/``, ``holes/``, the 100k dragon); the validation meshes (animation
first frames, the denoising pairs' clean meshes, saliency meshes, real scans, the 437k dragon)
informed no choice.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import machine_line, write_section  # noqa: E402
from spectrageo.compress._connectivity import (  # noqa: E402
    _encode_delta,
    decode_faces,
    encode_faces,
    reorder,
)
from spectrageo.datasets import data_dir  # noqa: E402
from spectrageo.datasets.splits import cases  # noqa: E402


def _rcm_delta(F: np.ndarray, n: int) -> int:
    import scipy.sparse as sp
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    E = np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]
    C = sp.csr_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
    C = ((C + C.T) > 0).astype(np.float64).tocsr()
    perm = reverse_cuthill_mckee(C, symmetric_mode=True).astype(np.int64)[::-1].copy()
    inv = np.empty(n, dtype=np.int64)
    inv[perm] = np.arange(n)
    G = inv[F]
    rot = np.argmin(G, axis=1)
    G = np.take_along_axis(G, (rot[:, None] + np.arange(3)[None, :]) % 3, axis=1)
    G = G[np.lexsort((G[:, 2], G[:, 1], G[:, 0]))]
    return len(_encode_delta(G))


def _draco1(V, F) -> float:
    try:
        import DracoPy
    except ImportError:
        return float("nan")
    b = DracoPy.encode(V, F.astype(np.uint32), quantization_bits=1, compression_level=10)
    return float(len(b))


def _meshes(root: Path):
    """``(split, path)`` of the split registry's ``connectivity`` cases present under ``root``."""
    return [(c.split, root / c.file) for c in cases("connectivity") if (root / c.file).exists()]


def _load(path: Path):
    if path.suffix == ".npz":
        with np.load(path) as z:
            return np.asarray(z["vertices"][0], dtype=np.float64), np.asarray(z["faces"], np.int64)
    from spectrageo.io import read_mesh

    m = read_mesh(path)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def _name(root: Path, path: Path) -> str:
    rel = path.relative_to(root).as_posix()
    if rel.endswith("/Original.obj"):
        rel = rel[: -len("/Original.obj")]
    return rel


def main() -> None:
    argparse.ArgumentParser(description=__doc__.split("\n\n")[0]).parse_args()
    root = data_dir(required=True)
    rows = []
    for split, path in _meshes(root):
        if not path.exists():
            continue
        V, F = _load(path)
        n, m = len(V), len(F)
        if m == 0:
            continue
        t0 = time.perf_counter()
        kept = encode_faces(F)
        t1 = time.perf_counter()
        G = decode_faces(kept, n, m)
        t2 = time.perf_counter()
        assert np.array_equal(G, F), path
        _, R, _ = reorder(V, F)
        re = encode_faces(R)
        assert np.array_equal(decode_faces(re, n, m), R), path
        bound = (math.lgamma(n + 1) + math.lgamma(m + 1)) / math.log(2)
        rows.append(
            {
                "split": split,
                "mesh": _name(root, path),
                "n": n,
                "m": m,
                "delta": 8 * len(_encode_delta(F)) / n,
                "kept": 8 * len(kept) / n,
                "bound": bound / n,
                "rcm": 8 * _rcm_delta(F, n) / n,
                "reorder": 8 * len(re) / n,
                "draco1": 8 * _draco1(V, F) / n,
                "enc_s": t1 - t0,
                "dec_s": t2 - t1,
            }
        )
        print(f"{rows[-1]['mesh']}: {rows[-1]['kept']:.2f} bpv", file=sys.stderr, flush=True)
    cols = (
        "split",
        "mesh",
        "n",
        "m",
        "delta",
        "kept",
        "bound",
        "rcm",
        "reorder",
        "draco1",
        "enc_s",
        "dec_s",
    )

    def cell(r, c):
        v = r[c]
        if isinstance(v, float):
            return "-" if not np.isfinite(v) else (f"{v:.3f}" if c.endswith("_s") else f"{v:.2f}")
        return str(v)

    lines = [
        "## Connectivity coding (order kept)",
        "",
        f"Produced by `python benchmarks/connectivity.py`. Machine: {machine_line()}. "
        + __doc__.split("\n\n", 2)[2].replace("\n", " ").replace("``", "`").strip(),
        "",
        "| split | meshes | delta (median) | kept (median) | kept / delta (median) | kept <= bound | rcm (median) | reorder (median) | draco1 (median) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for split in ("tuning", "validation"):
        rs = [r for r in rows if r["split"] == split]
        if not rs:
            continue
        mean = {
            c: float(np.nanmedian([r[c] for r in rs]))
            for c in ("delta", "kept", "rcm", "reorder", "draco1")
        }
        ratio = float(np.median([r["kept"] / r["delta"] for r in rs]))
        below = sum(r["kept"] <= r["bound"] for r in rs)
        lines.append(
            f"| {split} | {len(rs)} | {mean['delta']:.2f} | {mean['kept']:.2f} | {ratio:.2f} | "
            f"{below}/{len(rs)} | {mean['rcm']:.2f} | {mean['reorder']:.2f} | {mean['draco1']:.2f} |"
        )
    lines += ["", "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(cell(r, c) for c in cols) + " |" for r in rows]
    write_section("connectivity", "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
