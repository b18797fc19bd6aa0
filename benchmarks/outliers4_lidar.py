"""Further passes of ``remove_outliers(method="rpca")`` after the second (``static.RESCORE_FOUND``,
``static.RESCORE_LIFT``, ``static.RESCORE_PASSES``), tuning split only.

``--diagnose``: on the LiDAR tuning tiles at ``--fraction`` injected (far + near 5-15), which
injected outliers the defaults miss: recall by kind and by distance to the nearest clean point
(in spacings), the first pass's scores and ``k``-th neighbour distances of the missed, caught and
clean points, and the counts of the stages (do-no-harm rule, sparse-region stage, clusters).

Default: per tuning case of ``--task`` (``outliers-scantypes``: clean, 10 / 30 % injected,
bands; ``outliers``: the pattern split), ``rpca`` with ``RESCORE_PASSES = 2`` (the second pass
alone) and at its defaults, the passes that stood, and the share of the cloud and the lift
(median score of the removed points over the threshold) of the first tried pass (the pass after
the second, on the points the second pass keeps; organized frames: after their grid stage).

``--table``: the scan-type benchmark on the tuning split only (the rows of
``spectrageo evaluate outliers --methods scan-types``, split ``tuning``).

    python benchmarks/outliers4_lidar.py --data /work/shared/data [--task outliers] [--table]
See docs/decisions.md#outliers4-rescore-passes.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

import spectrageo.outliers.static as st
from outliers3_harm import _cell, _f1, _pattern_cases, _scan_type_cases


def _tried(Q, opts) -> tuple[str, object]:
    """``(cell of the second pass alone, (share, lift) of the pass after it or None)``."""
    passes = st.RESCORE_PASSES
    st.RESCORE_PASSES = 2
    try:
        r = st.detect_outliers(Q, options=opts)
    finally:
        st.RESCORE_PASSES = passes
    if "rescore" not in r.info:
        return r, None
    sub = np.flatnonzero(r.keep)
    o = replace(opts, grid=None, viewpoint=opts.sensor_origin)
    keep, r2, tau = st._rpca_pass(Q[sub], 10, o, None, "valley", False, -1, "cpu", {}, first=False)
    if r.info["rescore"]["local"]:
        keep |= ~st._locally_sparse(r2)
    found = np.count_nonzero(~keep)
    lift = float(np.median(r2.scores[~keep])) / tau if found else 0.0
    return r, (found / Q.shape[0], lift)


def sweep(data: Path, task: str, names) -> None:
    cases = _pattern_cases(data) if task == "outliers" else _scan_type_cases(data, names)
    print("| case | second pass alone | defaults | passes | tried pass: share, lift |")
    print("|---|---|---|---|---|")
    f1s: dict = {"two": [], "default": []}
    for label, Q, lab, band, opts in cases:
        two, tried = _tried(Q, opts)
        r = st.detect_outliers(Q, options=opts)
        if lab.any() and band is None:
            f1s["two"].append(_f1(~two.keep, lab))
            f1s["default"].append(_f1(~r.keep, lab))
        t = "-" if tried is None else f"{tried[0]:.4f}, {tried[1]:.2f}"
        n = r.info.get("rescore", {}).get("n_passes", 1)
        print(f"| {label} | {_cell(~two.keep, lab, band)} | {_cell(~r.keep, lab, band)} | {n} "
              f"| {t} |", flush=True)  # fmt: skip
    print("\nmean F1 of the contaminated cases: "
          + ", ".join(f"{k} {np.mean(v):.4f}" for k, v in f1s.items()))  # fmt: skip


def diagnose(data: Path, fraction: float) -> None:
    from scipy.spatial import cKDTree

    from spectrageo import io
    from spectrageo.evaluate._outliers_scans import _inject, scan_path
    from spectrageo.geometry import pca_normals

    for rel in ("lidar/pdal_4_6_crop.las", "lidar/pdal_hexbin_crop.las"):
        P = io.read(scan_path(data, rel), kind="points").points
        N = pca_normals(P, 10, orient="none")
        Q, lab, band, _ = _inject(P, N, fraction, 0)
        opts = st.RPCAOptions()
        info: dict = {}
        keep1, r, tau = st._rpca_pass(Q, 10, opts, None, "valley", False, -1, "cpu", info)
        res = st.detect_outliers(Q, options=opts)
        rem = ~res.keep
        h = res.info["spacing"]
        dc = cKDTree(P).query(Q, 1)[0] / h
        print(f"\n## {rel} at {fraction:g}: F1 {_f1(rem, lab):.3f}, tau {tau:.3f}, first pass "
              f"removed {1 - keep1.mean():.4f}, stages {info}, "
              f"second pass {res.info.get('rescore', res.info.get('rescore_dropped'))}")  # fmt: skip
        print("| kind | distance to clean (spacings) | n | recall |\n|---|---|---|---|")
        for kind, m in (("far", band == 0), ("near 5-15", band == 1)):
            for lo, hi in ((0, 1), (1, 2), (2, 3), (3, 5), (5, np.inf)):
                mm = m & (dc >= lo) & (dc < hi)
                if mm.any():
                    print(f"| {kind} | {lo}-{hi} | {mm.sum()} | {rem[mm].mean():.3f} |")
        s, d = r.scores / tau, r.kth_distance / np.median(r.kth_distance)
        print("| first pass | score / tau q10 / q50 / q90 | d_k / median q10 / q50 / q90 |")
        print("|---|---|---|")
        for nm, m in (("missed", lab & ~rem), ("caught", lab & rem), ("clean", ~lab)):
            qs, qd = np.quantile(s[m], [0.1, 0.5, 0.9]), np.quantile(d[m], [0.1, 0.5, 0.9])
            print(f"| {nm} | " + " / ".join(f"{x:.2f}" for x in qs) + " | "
                  + " / ".join(f"{x:.2f}" for x in qd) + " |")  # fmt: skip


def table(data: Path) -> None:
    from spectrageo.evaluate._outliers_scans import evaluate_scan_types, format_scan_types

    rows = evaluate_scan_types(data, splits=("tuning",))
    print("\n".join(format_scan_types(rows)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="/work/shared/data")
    ap.add_argument(
        "--task", default="outliers-scantypes", choices=("outliers", "outliers-scantypes")
    )
    ap.add_argument("--cases", default="", help="comma-separated scan-type case names")
    ap.add_argument("--diagnose", action="store_true")
    ap.add_argument("--fraction", type=float, default=0.3)
    ap.add_argument("--table", action="store_true")
    a = ap.parse_args()
    data = Path(a.data)
    if a.diagnose:
        diagnose(data, a.fraction)
    elif a.table:
        table(data)
    else:
        sweep(data, a.task, set(a.cases.split(",")) if a.cases else None)


if __name__ == "__main__":
    main()
