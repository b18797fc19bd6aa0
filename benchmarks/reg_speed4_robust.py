"""CPU time of the registration's robustification (Eq. 6.42-6.44) per pair: the full scores
against the decision-only path, on the clouds that ``spectrageo.register.register`` robustifies.

Pairs: the real scan pairs of a split of ``spectrageo evaluate register`` (bunny range scans and
the Open3D fragment pair). For each pair, the source down-sampled to ``MAX_POINTS`` and the
target to ``TARGET_POINTS * MAX_POINTS`` (as ``register`` does) are robustified two ways,
alternating, ``--repeats`` times, on one BLAS thread:

* full: the RPCA scores of every point (``_robust.outlier_result``) against the 0.6 threshold,
  and the boundary test's distances by ``np.square(P[nbrs] - P[:, None]).sum(axis=2)``;
* decision: ``_robust_fast.outlier_keep`` and ``_robust.boundary_mask`` with the RPCA's
  neighbours.

Reported: CPU seconds per pair (process time, median over the repeats; the k-d tree queries of
the targets above 16,384 points use all cores in both), the stages of the decision path, and the
number of points whose kept/removed status differs between the two (0 expected).

    python benchmarks/reg_speed4_robust.py [--split tuning|validation] [--repeats 5]

Writes ``benchmarks/_out/reg_speed4_robust.md``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, write_section  # noqa: E402


def _full(P: np.ndarray) -> np.ndarray:
    from spectrageo.register._robust import exact_neighbors, outlier_result

    res = outlier_result(P, 10)
    keep = res.scores <= 0.6
    nb = exact_neighbors(res)
    d_psi = np.sqrt(np.square(P[nb] - P[:, None, :]).sum(axis=2)).mean(axis=1)
    return keep & ~(d_psi >= 2.0 * float(d_psi.mean()))


def _decision(P: np.ndarray) -> np.ndarray:
    from spectrageo.register._robust import boundary_mask
    from spectrageo.register._robust_fast import outlier_keep

    keep, nb, _ = outlier_keep(P, 10, 0.6)
    return keep & ~boundary_mask(P, 10, nb)


def _stages(clouds: list[np.ndarray]) -> dict[str, float]:
    """CPU seconds of the decision path's stages over ``clouds`` (wrapped functions)."""
    from spectrageo.outliers import _rpca_numpy as rn
    from spectrageo.register import _robust, _robust_fast

    acc: dict[str, float] = {}
    saved = []

    def wrap(mod, attr, name):
        f = getattr(mod, attr)
        saved.append((mod, attr, f))

        def g(*a, **kw):
            t = time.process_time()
            try:
                return f(*a, **kw)
            finally:
                acc[name] = acc.get(name, 0.0) + time.process_time() - t

        setattr(mod, attr, g)

    wrap(_robust_fast, "_knn", "kNN (step 1)")
    wrap(rn, "_patches", "patch matrices")
    wrap(rn, "_ialm", "inexact ALM (step 3)")
    wrap(_robust_fast, "_rebuild", "rebuilt patches (step 5)")
    wrap(rn, "_replay", "replayed pass (step 5)")
    wrap(rn, "_normals", "normals (step 7)")
    wrap(_robust, "boundary_mask", "boundary test")
    try:
        t0 = time.process_time()
        for P in clouds:
            _decision(P)
        acc["total"] = time.process_time() - t0
    finally:
        for mod, attr, f in saved:
            setattr(mod, attr, f)
    return acc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=("tuning", "validation"), default="tuning")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    from spectrageo.datasets import data_dir
    from spectrageo.evaluate import register as ev
    from spectrageo.register._api import MAX_POINTS, TARGET_POINTS
    from spectrageo.register._common import downsample_to

    warnings.simplefilter("ignore")
    data = Path(data_dir(required=True))
    cfg = ev.VALIDATION if args.split == "validation" else ev.TUNING
    pairs = ev.pairs_for(data, cfg, ("bunny", "open3d"))
    clouds = []
    for p in pairs:
        clouds += [downsample_to(p["source"], MAX_POINTS),
                   downsample_to(p["target"], int(TARGET_POINTS * MAX_POINTS))]  # fmt: skip
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        _full(clouds[0]), _decision(clouds[0])  # warm-up
        ref = [_full(P) for P in clouds]
        got = [_decision(P) for P in clouds]
        n_diff = sum(int(np.count_nonzero(a != b)) for a, b in zip(ref, got))
        t_full, t_dec = [], []
        for _ in range(args.repeats):
            for fn, out in ((_full, t_full), (_decision, t_dec)):
                t0 = time.process_time()
                for P in clouds:
                    fn(P)
                out.append((time.process_time() - t0) / len(pairs))
        stages = _stages(clouds)
    load = os.getloadavg()
    a, b = float(np.median(t_full)), float(np.median(t_dec))
    lines = [
        "## Robustification of the registration: decision only (issue 50)",
        "",
        f"`python benchmarks/reg_speed4_robust.py --split {args.split} --repeats {args.repeats}`; "
        f"{len(pairs)} pairs, {len(clouds)} clouds ({sum(P.shape[0] for P in clouds)} points), "
        "CPU seconds per pair (process time), one BLAS thread, runs alternating.",
        "",
        f"Split: {args.split}. {machine_line()}; load average {load[0]:.1f} at the end.",
        "",
        "| path | CPU s per pair, median | min | max |",
        "|---|---:|---:|---:|",
        f"| full scores | {a:.4f} | {min(t_full):.4f} | {max(t_full):.4f} |",
        f"| decision only | {b:.4f} | {min(t_dec):.4f} | {max(t_dec):.4f} |",
        "",
        f"- ratio {b / a:.2f}; points whose kept/removed status differs: {n_diff}",
        "- stages of the decision path (one pass, CPU s per pair): "
        + ", ".join(f"{k} {v / len(pairs):.4f}" for k, v in stages.items()),
    ]
    write_section("reg_speed4_robust", "\n".join(lines))


if __name__ == "__main__":
    main()
