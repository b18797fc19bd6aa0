"""``--reorder`` connectivity: format and size of each ``compress`` case, and whether the
reordered faces are a fixed point of the traversal (docs/decisions.md#codec-conn-fixed-point).

    python benchmarks/canon_fixed_point.py [--large]   # prints a markdown table

Columns: the split of the registry's ``compress`` collection, vertices, the connectivity code's
first byte (0x43 inline) and size, bits per vertex, ``fixed`` (``canonical`` of the reordered
faces returns them unchanged) and the best of three times of ``canonical``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from spectrageo.compress import _conn_traverse
from spectrageo.compress._connectivity import reorder_coded
from spectrageo.datasets import data_dir
from spectrageo.datasets._split_compress import COMPRESS_LARGE
from spectrageo.datasets.splits import cases
from spectrageo.io import read_mesh


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--large", action="store_true", help="include the 437k-vertex dragon")
    args = ap.parse_args()
    root = data_dir(required=True)
    print("| split | mesh | n | format | bytes | bpv | fixed | canonical (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for c in cases("compress"):
        if c.file in COMPRESS_LARGE and not args.large:
            continue
        m = read_mesh(root / c.file)
        V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
        n = len(V)
        ts = []
        for _ in range(3):
            t = time.perf_counter()
            _conn_traverse.canonical(F, n)
            ts.append(time.perf_counter() - t)
        _, G, _, code = reorder_coded(V, F)
        fixed = np.array_equal(_conn_traverse.canonical(G, n)[1], G)
        print(
            f"| {c.split} | {c.file} | {n} | 0x{code[0]:02x} | {len(code)} | "
            f"{8 * len(code) / n:.3f} | {fixed} | {min(ts):.3f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
