"""CPU time of the ``pca-pred`` ``error=`` encode (issue 51), per stage, one run.

    python benchmarks/anim_speed_pca_pred.py [--profile] [--reorder] [--against FILE] [NAME ...]

For every named animation of the split registry's ``compress-animation`` task (default: the
tuning horse-gallop and the validation crane; the split named in every row): the KG errors of
Draco per frame at 10 and 12 bits (default mode, as in ``benchmarks/anim_pca_pred.py``; cached in
``_out/anim_speed_draco.json``), then ``pca-pred`` with ``error=`` each of them: CPU seconds
(``time.process_time``, the machine being shared) of the encode call (``--reorder``: with
``reorder=True``, KG through the known permutation), per stage (analysis, PCA
projection, coefficient coder, error of a trial, file build), the number of rate-search trials
(``trials``: errors of coded and of rounded coefficients; ``coder_calls``: coded trials;
``n_projections``: projections on the quantised basis, where the module has them),
the size and the SHA-256 of the file (the same bits before and after a speed change). With
``--against FILE`` (an earlier ``_pca_pred.py``, e.g. from ``git show``) every encode runs with
that module and with the current one alternately (``module`` column: which).

    python benchmarks/anim_speed_pca_pred.py --searches-against FILE [NAME ...]

runs the ``error=`` step search of an earlier ``_rate_animation.py`` and the current one
alternately on one ``reorder=True`` encoder at 12 KG targets, 0.02-0.3 % (:func:`searches`).
"""

from __future__ import annotations

import argparse
import cProfile
import hashlib
import importlib.util
import json
import math
import os
import pstats
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from spectrageo import compress, io
from spectrageo.compress import _pca_pred
from spectrageo.compress._connectivity import reorder_coded
from spectrageo.datasets import splits
from spectrageo.evaluate.compress_animation import _draco
from spectrageo.metrics import kg_error

DATA = Path(os.environ.get("SPECTRAGEO_DATA", "../shared/data"))
OUT = Path(__file__).resolve().parent / "_out"


def _cases(names):
    out = []
    for sp in ("tuning", "validation"):
        for rel in splits.files("compress-animation", sp):
            name = Path(rel).stem
            if name in (names or ("horse-gallop", "crane")):
                out.append((sp, name, DATA / rel))
    return out


def _draco_kgs(name, A, F):
    cache = OUT / "anim_speed_draco.json"
    known = json.loads(cache.read_text()) if cache.exists() else {}
    if name not in known:
        known[name] = {str(b): kg_error(_draco(A, F, b, False)[1], A) for b in (10, 12)}
        OUT.mkdir(exist_ok=True)
        cache.write_text(json.dumps(known, indent=1))
    return {int(b): v for b, v in known[name].items()}


def _stages(mod):
    return (
        (mod.PcaPredEncoder, "__init__", "analysis"),
        (mod.PcaPredEncoder, "project", "project"),
        (mod.PcaPredEncoder, "_project", "projections"),
        (mod, "encode_coefficients", "coder"),
        (mod.PcaPredFileEncoder, "sq_error", "trial error"),
        (mod.PcaPredFileEncoder, "build", "build"),
    )


def _load(path):
    """An earlier ``_pca_pred.py`` as a module of the package (its relative imports resolve)."""
    spec = importlib.util.spec_from_file_location("spectrageo.compress._pca_pred_before", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def _timed(mod, times, counts):
    """Wrap the stages with CPU timers (nested stages counted in each, as they run)."""
    saved = []
    for owner, attr, label in _stages(mod):
        f = getattr(owner, attr, None)
        if f is None:  # a stage an earlier module does not have
            continue
        saved.append((owner, attr, f))

        def w(*a, _f=f, _l=label, **k):
            t = time.process_time()
            try:
                return _f(*a, **k)
            finally:
                times[_l] += time.process_time() - t
                counts[_l] += 1

        setattr(owner, attr, w)
    return saved


def run(names=(), profile=False, against=None, reorder=False):
    rows = []
    mods = [("current", _pca_pred)]
    if against:
        mods = [("before", _load(against)), *mods]
    for sp, name, path in _cases(names):
        a = io.read(path)
        A, F = np.asarray(a.frames, dtype=np.float64), a.faces
        ref = A[:, reorder_coded(A[0], F)[2]] if reorder else A
        for (bits, kg), (label, mod) in (
            (t, m) for t in sorted(_draco_kgs(name, A, F).items()) for m in mods
        ):
            sys.modules["spectrageo.compress._pca_pred"] = mod
            times, counts = defaultdict(float), defaultdict(int)
            saved = _timed(mod, times, counts)
            prof = cProfile.Profile() if profile else None
            t0 = time.process_time()
            if prof:
                prof.enable()
            data = compress.encode_animation(A, F, method="pca-pred", error=kg, reorder=reorder)
            if prof:
                prof.disable()
            cpu = time.process_time() - t0
            for owner, attr, f in saved:
                setattr(owner, attr, f)
            sys.modules["spectrageo.compress._pca_pred"] = _pca_pred
            R, _F = compress.decode_animation(data)
            row = {
                "split": sp,
                "model": name,
                "target": f"kg=draco{bits} ({kg:.5g})",
                "module": label,
                "reorder": reorder,
                "cpu_s": round(cpu, 2),
                "trials": counts["trial error"],
                "coder_calls": counts["coder"],
                "n_projections": counts["projections"],
                "bpvf": round(8.0 * len(data) / (A.shape[0] * A.shape[1]), 4),
                "kg": round(kg_error(R, ref), 5),
                "sha256": hashlib.sha256(data).hexdigest()[:16],
                **{k: round(v, 2) for k, v in times.items()},
            }
            rows.append(row)
            print(row, flush=True)
            if prof:
                pstats.Stats(prof).sort_stats("cumulative").print_stats(25)
    return rows


def searches(names, against, lo=0.02, hi=0.3, count=12):
    """The ``error=`` step search of an earlier ``_rate_animation.py`` (``against``) and the
    current one, alternately on one ``reorder=True`` encoder, at ``count`` KG targets log-spaced
    in ``[lo, hi]`` percent: coded and rounded trials, the decoded error, bpvf, search CPU s."""
    from spectrageo.compress import _rate_animation
    from spectrageo.compress._animation import make_encoder

    spec = importlib.util.spec_from_file_location("spectrageo.compress._rate_before", against)
    before = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = before
    spec.loader.exec_module(before)
    rows = []
    for sp, name, path in _cases(names):
        a = io.read(path)
        A, F = np.asarray(a.frames, dtype=np.float64), a.faces
        _V, F, perm, _c = reorder_coded(A[0], F)
        A = A[:, perm]
        enc = make_encoder(A, F, "pca-pred", {})
        enc.reordered = True
        den = float(np.linalg.norm(A - A.mean(axis=1, keepdims=True)))
        sq, n = enc.sq_error, defaultdict(int)

        def counted(s, rounded=False, _sq=sq, _n=n):
            _n["rounded" if rounded else "coded"] += 1
            return _sq(s, rounded) if rounded else _sq(s)

        enc.sq_error = counted
        for kg in np.geomspace(lo, hi, count):
            for label, mod in (("before", before), ("current", _rate_animation)):
                for _t, p in enc.parts:  # no trial cached from the other search
                    p._q, p._p = {}, {}
                n.clear()
                t0 = time.process_time()
                s, data = mod.pred_rate_search(enc, A, None, None, float(kg))
                cpu = time.process_time() - t0
                got = 100.0 * math.sqrt(sq(s)) / den
                row = {
                    "split": sp,
                    "model": name,
                    "target": round(float(kg), 5),
                    "module": label,
                    "coded": n["coded"],
                    "rounded": n["rounded"],
                    "kg": round(got, 5),
                    "bpvf": round(8.0 * len(data) / (A.shape[0] * A.shape[1]), 4),
                    "search_cpu_s": round(cpu, 2),
                }
                rows.append(row)
                print(row, flush=True)
    return rows


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--against", default=None)
    ap.add_argument("--reorder", action="store_true")
    ap.add_argument("--searches-against", default=None)
    ap.add_argument("names", nargs="*")
    args = ap.parse_args()
    if args.searches_against:
        searches(tuple(args.names), args.searches_against)
    else:
        run(tuple(args.names), args.profile, args.against, args.reorder)
