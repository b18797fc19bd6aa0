"""``pca-pred`` against Draco per frame and the thesis's variants (issue 51), one run.

    python benchmarks/anim_pca_pred.py [--split tuning|validation|both] [NAME ...]

For every animation of the split registry's ``compress-animation`` task (split named in every
row): Draco per frame through DracoPy at 10 and 12 quantisation bits (default mode at
compression level 10, which reorders vertices, KG after nearest-vertex matching: a lower bound;
and order-preserving); then ``pca-pred`` with ``error=`` set to each Draco KG error, with
``reorder=True`` (against Draco's default mode; KG exact through the known permutation) and
order kept (against order-preserving Draco); the thesis's ``blocks`` and ``pca-qp`` at the same
errors and at 4x Draco-10's and a quarter of Draco-12's KG; and ``pca-pred`` at whole-file
``bpvf=`` 0.5 and 1.0 (Table 5.12's ``q_s`` range), the KG error there. Encode times in this
process.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, write_section  # noqa: E402
from rate_animation import _fmt  # noqa: E402
from spectrageo import InvalidInputError, compress, io  # noqa: E402
from spectrageo.compress._connectivity import reorder_coded  # noqa: E402
from spectrageo.datasets import splits  # noqa: E402
from spectrageo.evaluate.compress_animation import _draco  # noqa: E402
from spectrageo.metrics import kg_error  # noqa: E402

DATA = Path(os.environ.get("SPECTRAGEO_DATA", "../shared/data"))
COLUMNS = ("split", "model", "method", "target", "bpvf", "kg", "vs_draco", "seconds")


def _cases(split, names):
    out = []
    for sp in ("tuning", "validation") if split == "both" else (split,):
        for rel in splits.files("compress-animation", sp):
            name = Path(rel).stem
            if not names or name in names:
                out.append((sp, name, DATA / rel))
    return out


def _encode(A, F, method, perm=None, **kw):
    t0 = time.perf_counter()
    try:
        data = compress.encode_animation(A, F, method=method, **kw)
    except InvalidInputError as exc:
        return {"kg": str(exc).split(":")[0] + ": unreachable"}
    dt = time.perf_counter() - t0
    R, _F = compress.decode_animation(data)
    ref = A if perm is None else A[:, perm]
    return {
        "bpvf": 8.0 * len(data) / (A.shape[0] * A.shape[1]),
        "kg": kg_error(R, ref),
        "seconds": dt,
    }


def run(split="both", names=()) -> list[dict]:
    rows = []
    for sp, name, path in _cases(split, names):
        a = io.read(path)
        A, F = np.asarray(a.frames, dtype=np.float64), a.faces
        T, n = A.shape[:2]
        perm = reorder_coded(A[0], F)[2]
        base = {"split": sp, "model": name}
        ref = {}
        for bits in (10, 12):
            for ordered in (False, True):
                nb, R, te, _td, _o = _draco(A, F, bits, ordered)
                peer = "draco-ordered" if ordered else "draco"
                r = {**base, "method": peer, "target": f"q={bits}", "bpvf": 8.0 * nb / (T * n)}
                r.update(kg=kg_error(R, A), seconds=te)
                rows.append(r)
                ref[(peer, bits)] = r
                print(r, flush=True)

        def add(method, target, peer, base=base, A=A, F=F, perm=perm, **kw):
            r = {**base, "method": method, "target": target}
            p = perm if kw.get("reorder") else None
            r.update(_encode(A, F, method.split("+")[0], p, **kw))
            if "bpvf" in r and peer is not None:
                r["vs_draco"] = r["bpvf"] / peer["bpvf"]
            rows.append(r)
            print(r, flush=True)

        k10, k12 = ref[("draco", 10)]["kg"], ref[("draco", 12)]["kg"]
        for bits, kg in ((10, k10), (12, k12)):
            add("pca-pred+reorder", f"kg=draco{bits}", ref[("draco", bits)], error=kg, reorder=True)
            add("pca-pred", f"kg=draco{bits}", ref[("draco-ordered", bits)], error=kg)
        for m in ("blocks", "pca-qp"):
            for bits, kg in ((10, k10), (12, k12)):
                add(m, f"kg=draco{bits}", ref[("draco-ordered", bits)], error=kg)
        for label, kg in (("4x draco10", 4 * k10), ("draco12/4", k12 / 4)):
            for m in ("pca-pred", "blocks"):
                add(m, f"kg={label}", None, error=kg)
        for b in (0.5, 1.0):
            add("pca-pred", f"bpvf={b:g}", None, bpvf=b)
            add("pca-pred+reorder", f"bpvf={b:g}", None, bpvf=b, reorder=True)
    return rows


def markdown(rows) -> str:
    head = (
        "## pca-pred against Draco per frame and the thesis's variants (issue 51)\n\n"
        f"{machine_line()}\n\n"
        "`python benchmarks/anim_pca_pred.py`. `kg=dracoB`: `error=` set to the KG error of "
        "Draco per frame at B bits (default mode, nearest-vertex matching: a lower bound); "
        "`vs_draco`: bpvf / Draco's bpvf at that point, against Draco's default mode for "
        "`+reorder` rows and order-preserving Draco otherwise; `seconds`: the encode, rate "
        "control included.\n\n"
    )
    table = [list(COLUMNS), ["---"] * len(COLUMNS)]
    table += [[_fmt(r.get(c)) for c in COLUMNS] for r in rows]
    return head + "".join(f"| {' | '.join(t)} |\n" for t in table)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--split", default="both", choices=("tuning", "validation", "both"))
    ap.add_argument("names", nargs="*")
    args = ap.parse_args()
    result = run(args.split, tuple(args.names))
    name = f"anim_pca_pred_{args.split}"
    (Path(__file__).resolve().parent / "_out").mkdir(exist_ok=True)
    with open(Path(__file__).resolve().parent / "_out" / f"{name}.csv", "w", newline="") as fh:
        csv.DictWriter(fh, fieldnames=COLUMNS, extrasaction="ignore").writeheader()
        csv.DictWriter(fh, fieldnames=COLUMNS, extrasaction="ignore").writerows(result)
    write_section(name, markdown(result))
