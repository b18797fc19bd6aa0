"""Where ``pca-pred``'s bits go on one animation, and its rate at given KG errors.

    python benchmarks/anim_pred2_split.py [NAME] [--reorder] [--split-bits]

Codes the animation (order kept, or in the connectivity coder's order with ``--reorder``) at
steps bracketing each target KG error (Draco per frame at 10 and 12 bits on horse-gallop by
default) and prints bpvf (basis + coefficients, no connectivity) log-interpolated at each
target; with ``--split-bits`` the split of the bits at the finest step: basis, flags, and the
coefficients of groups of components (each group's size from prefix codes of the first ``k``
components, exact: component ``j`` is coded from components before it only).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from spectrageo import io
from spectrageo.compress import _pca_pred as pp
from spectrageo.compress._animation import frame_box
from spectrageo.compress._connectivity import reorder_coded
from spectrageo.metrics import kg_error

DATA = Path(os.environ.get("SPECTRAGEO_DATA", "../shared/data"))
#: Draco per frame's KG errors (%) at 10 and 12 bits on horse-gallop (tuning)
TARGETS = {"horse-gallop": ((0.145, (8.5e-4, 1.05e-3)), (0.0362, (2.1e-4, 2.5e-4)))}


def measure(A, F, steps):
    """``{step: (bpvf, kg, basis bits, coefficient bits)}`` of the coder on ``A`` (T, n, 3)."""
    T, n = A.shape[:2]
    origin, scale = frame_box(A)
    enc = pp.PcaPredFileEncoder(A, F, 512, origin, scale)
    out = {}
    for s in steps:
        ch = enc.parts[0][1].chunks(s)
        nb = 8.0 * len(ch[0][1])
        nc = 8.0 * len(ch[1][1])
        out[s] = ((nb + nc) / (T * n), kg_error(enc.frames(s), A), nb, nc)
    return enc, out


def at_kg(pts, kg):
    """bpvf at ``kg``, log-log interpolated between two ``(bpvf, kg)`` points."""
    (b0, k0), (b1, k1) = pts
    t = (math.log(kg) - math.log(k0)) / (math.log(k1) - math.log(k0))
    return math.exp(math.log(b0) + t * (math.log(b1) - math.log(b0)))


def split_bits(enc, s):
    part = enc.parts[0][1]
    C = part.project(s)[4]
    k = C.shape[1]
    cuts = [c for c in (1, 2, 3, 6, 12, 24, 48, 96) if c < k] + [k]
    prev, last = 0.0, 0
    nv = part.n * part.T
    print(f"k = {k}; coefficient bits per vertex-frame by component group (flags included):")
    for c in cuts:
        chunk = pp.encode_coefficients(C[:, :c], part.plan, pp.RDO_LAMBDA)[0]
        b = 8.0 * len(chunk) / nv
        print(f"  components {last}-{c - 1}: {b - prev:.4f}")
        prev, last = b, c


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("name", nargs="?", default="horse-gallop", choices=sorted(TARGETS))
    ap.add_argument("--reorder", action="store_true")
    ap.add_argument("--split-bits", action="store_true")
    args = ap.parse_args()
    a = io.read(DATA / "animations" / f"{args.name}.npz")
    A, F = np.asarray(a.frames, dtype=np.float64), a.faces
    if args.reorder:
        _V, F, perm, _c = reorder_coded(A[0], F)
        A = A[:, perm]
    t0 = time.perf_counter()
    steps = [s for _kg, ss in TARGETS[args.name] for s in ss]
    enc, res = measure(A, F, steps)
    for s in steps:
        b, kg, nb, nc = res[s]
        print(f"step {s:.3g}: bpvf {b:.4f} kg {kg:.5f} basis {nb / A.size * 3:.4f}")
    for kg, ss in TARGETS[args.name]:
        print(f"at KG {kg}: bpvf {at_kg([res[s][:2] for s in ss], kg):.4f}")
    if args.split_bits:
        split_bits(enc, steps[-2])
    print(f"{time.perf_counter() - t0:.1f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
