"""Rate control of the animation codecs (issue 51): time of ``error=`` / ``bpvf=`` encodes against a
fixed-step encode, and size at the KG errors of Draco per frame at 10 and 12 bits.

    python benchmarks/rate_animation.py [NAME ...]     # about 15 minutes for the six animations

For every animation of the split registry's ``compress-animation`` task (its split named in
every row): Draco per frame through DracoPy (default mode at compression level 10, which
reorders vertices, KG after nearest-vertex matching: a lower bound; and order-preserving) at 10
and 12 quantisation bits;
then the thesis's variants ``pca-q``, ``pca-qp`` (``pca-qs`` codes the same bits and decodes
serially) and ``blocks`` through their rate control with ``error=`` set to each Draco KG error,
and with ``bpvf=`` 0.5 and 1.0 (the range of Table 5.12's ``q_s``), the KG error there. Every
encode is timed in this process, next to a fixed-step encode of the same method; the KG error
and bpvf are measured on the decoded file.
"""

from __future__ import annotations

import csv
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, write_section  # noqa: E402
from spectrageo import compress, io  # noqa: E402
from spectrageo.datasets import splits  # noqa: E402
from spectrageo.evaluate.compress_animation import _draco  # noqa: E402
from spectrageo.metrics import kg_error  # noqa: E402

DATA = Path(os.environ.get("SPECTRAGEO_DATA", "../shared/data"))
METHODS = ("blocks", "pca-qp", "pca-q")
DRACO_BITS = (10, 12)
BPVF = (0.5, 1.0)


def _cases(names):
    out = []
    for split in ("tuning", "validation"):
        for rel in splits.files("compress-animation", split):
            name = Path(rel).stem
            if not names or name in names:
                out.append((split, name, DATA / rel))
    return out


def _encode(A, F, method, **kw):
    """bpvf, KG error, encode seconds and trial count of one rate-controlled encode (the
    message, in ``kg``, when the target cannot be met)."""
    from spectrageo import InvalidInputError
    from spectrageo.compress import _rate_animation as ra

    seen = []
    orig = ra.Trials.symbols

    def symbols(self, s):
        if s not in self._syms:
            seen.append(s)
        return orig(self, s)

    ra.Trials.symbols = symbols
    try:
        t0 = time.perf_counter()
        data = compress.encode_animation(A, F, method=method, **kw)
        dt = time.perf_counter() - t0
    except InvalidInputError as exc:
        return {"kg": str(exc).split(":")[0] + ": unreachable", "seconds": time.perf_counter() - t0}
    finally:
        ra.Trials.symbols = orig
    R, _F = compress.decode_animation(data)
    return {
        "bpvf": 8.0 * len(data) / (A.shape[0] * A.shape[1]),
        "kg": kg_error(R, A),
        "seconds": dt,
        "trials": len(seen),
    }


def run(names=()) -> list[dict]:
    rows = []
    for split, name, path in _cases(names):
        a = io.read(path)
        A, F = np.asarray(a.frames, dtype=np.float64), a.faces
        T, n = A.shape[:2]
        base = {"split": split, "model": name, "frames": T, "vertices": n}
        ref = {}
        for bits in DRACO_BITS:
            for ordered in (False, True):
                nb, R, te, _td, _o = _draco(A, F, bits, ordered)
                peer = "draco-ordered" if ordered else "draco"
                r = {**base, "method": peer, "target": f"q={bits}", "bpvf": 8.0 * nb / (T * n)}
                r.update(kg=kg_error(R, A), seconds=te, trials=0)
                rows.append(r)
                ref[(peer, bits)] = r
                print(r, flush=True)
        for m in METHODS:
            t0 = time.perf_counter()
            compress.encode_animation(A, F, method=m)
            fixed = time.perf_counter() - t0
            rows.append({**base, "method": m, "target": "fixed step", "seconds": fixed})
            print(rows[-1], flush=True)
            for bits in DRACO_BITS:
                kg = ref[("draco", bits)]["kg"]
                r = {**base, "method": m, "target": f"kg=draco{bits}"}
                r.update(_encode(A, F, m, error=kg))
                if "bpvf" in r:
                    r["vs_draco"] = r["bpvf"] / ref[("draco", bits)]["bpvf"]
                    r["vs_draco_ordered"] = r["bpvf"] / ref[("draco-ordered", bits)]["bpvf"]
                rows.append(r)
                print(r, flush=True)
            for b in BPVF:
                r = {**base, "method": m, "target": f"bpvf={b:g}"}
                r.update(_encode(A, F, m, bpvf=b))
                rows.append(r)
                print(r, flush=True)
    return rows


COLUMNS = (
    "split",
    "model",
    "method",
    "target",
    "bpvf",
    "kg",
    "vs_draco",
    "vs_draco_ordered",
    "seconds",
    "trials",
)


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}"
    return "" if v is None else str(v)


def markdown(rows) -> str:
    lines = [
        "## Animation rate control and size at Draco's KG error (issue 51)",
        "",
        machine_line(),
        "",
        "`python benchmarks/rate_animation.py`. `kg=dracoB`: the codec's `error=` set to the KG "
        "error of Draco per frame at B bits (default mode; its KG is a lower bound after "
        "nearest-vertex matching); `vs_draco`: bpvf / Draco's bpvf at that point; `seconds`: "
        "the encode alone, rate control included; `trials`: trial quantisations of the search.",
        "",
        "| " + " | ".join(COLUMNS) + " |",
        "|" + "---|" * len(COLUMNS),
    ]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r.get(c)) for c in COLUMNS) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    rows = run(tuple(sys.argv[1:]))
    out = Path(__file__).resolve().parent / "_out"
    out.mkdir(exist_ok=True)
    with open(out / "rate_animation.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    print(write_section("rate_animation", markdown(rows)))


if __name__ == "__main__":
    main()
