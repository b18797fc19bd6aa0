"""The second pass of ``remove_outliers(method="rpca")`` when the locally sparse points bring the
first pass's removals to ``rescore_share`` (``static.RESCORE_AFTER_LOCAL``), tuning split only.

Per tuning case of ``--task`` (``outliers-scantypes``: clean, 10 / 30 % injected far + near,
the 1-3 / 3-5 / 5-15 spacing bands; ``outliers``: the pattern split), ``rpca`` at its defaults
with each configuration of ``--configs`` (``off``: the previous composition, ``on``), in the same
process; F1 with the clean points removed (%) in brackets, bands: recall per band; ``R`` marks a
case whose passes ran after the locally sparse test. ``--robot``: the horse-gallop robot
pipeline (halo 10 %, 12 frames; F1 and theta). ``--diagnose``: the injected outliers of
``--cases`` missed at the defaults, by where they lie against the clean points within two mean
spacings horizontally (above, below or inside their vertical extent, or an empty column) and by
their distance to the nearest clean point (mean spacings), with the first pass's share and the
locally sparse share of the cloud. ``--speed``: ``detect_outliers`` on the tuning tile
``pdal_4_6_crop`` repeated side by side (``--tiles``), clean and with 30 % injected, ``off`` and
``on`` alternately.

    python benchmarks/outliers6_lidar.py --data /work/shared/data [--task outliers] [--robot]
See docs/decisions.md#outliers6-rescore-after-local.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import spectrageo.outliers.static as st
from outliers3_harm import _cell, _f1, _pattern_cases, _scan_type_cases
from spectrageo.outliers import detect_outliers


def _with(cfg: str, fn):
    old = st.RESCORE_AFTER_LOCAL
    st.RESCORE_AFTER_LOCAL = cfg == "on"
    try:
        return fn()
    finally:
        st.RESCORE_AFTER_LOCAL = old


def cases_table(data: Path, task: str, configs: list, names) -> None:
    cases = _pattern_cases(data) if task == "outliers" else _scan_type_cases(data, names)
    print("| case | " + " | ".join(configs) + " |")
    print("|---" * (len(configs) + 1) + "|")
    f1s: dict = {c: [] for c in configs}
    times: dict = {c: 0.0 for c in configs}
    for label, Q, lab, band, opts in cases:
        cells = []
        for c in configs:
            t0 = time.perf_counter()
            r = _with(c, lambda Q=Q, opts=opts: detect_outliers(Q, options=opts))
            times[c] += time.perf_counter() - t0
            if lab.any() and band is None:
                f1s[c].append(_f1(~r.keep, lab))
            mark = " R" if r.info.get("rescore_after_local") else ""
            cells.append(_cell(~r.keep, lab, band) + mark)
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)
    print("\nmean F1 of the contaminated cases: "
          + ", ".join(f"{k} {np.mean(v):.4f}" for k, v in f1s.items()))  # fmt: skip
    print("seconds: " + ", ".join(f"{k} {v:.1f}" for k, v in times.items()))


def diagnose(data: Path, names, configs: list) -> None:
    from scipy.spatial import cKDTree

    from spectrageo.noise.corruption import mean_spacing

    bins = (0.0, 1.0, 2.0, 3.0, 5.0, 10.0, np.inf)
    for label, Q, lab, band, opts in _scan_type_cases(data, names):
        if not lab.any():
            continue
        P = Q[~lab]
        s = mean_spacing(P, None)
        ol = np.flatnonzero(lab)
        dn = cKDTree(P).query(Q[ol])[0] / s
        cols = cKDTree(P[:, :2]).query_ball_point(Q[ol, :2], 2.0 * s)
        zr = np.array([(P[c, 2].min(), P[c, 2].max()) if c else (np.nan, np.nan) for c in cols])
        z = Q[ol, 2]
        where = np.where(z > zr[:, 1], "above", np.where(z < zr[:, 0], "below", "inside"))
        where[np.isnan(zr[:, 0])] = "empty"
        for c in configs:
            r = _with(c, lambda Q=Q, opts=opts: detect_outliers(Q, options=opts))
            _diagnosis(f"{label} ({c})", r, lab, band, ol, where, dn, s, bins)


def _diagnosis(label, r, lab, band, ol, where, dn, s, bins) -> None:
    rem = ~r.keep
    n_local = r.info.get("n_locally_sparse", 0)
    first = "" if "rescore" in r.info else (
        f", first pass {1.0 - (np.count_nonzero(r.keep) + n_local) / r.keep.size:.4f}")  # fmt: skip
    print(f"{label}: recall {rem[lab].mean():.3f}, mean spacing {s:.3g}{first}, locally "
          f"sparse {n_local / r.keep.size:.4f}")  # fmt: skip
    for w in ("above", "below", "inside", "empty"):
        m = where == w
        if band is not None:
            rec = [f"{rem[ol][m & (band[ol] == b)].mean():.2f}" for b in range(3)]
            print(f"  {w}: {m.sum()}, bands recall {' / '.join(rec)}")
            continue
        cells = [
            f"[{a:g},{b:g}) {np.count_nonzero(mm)}: {rem[ol][mm].mean():.2f}"
            for a, b in zip(bins[:-1], bins[1:])
            if (mm := m & (dn >= a) & (dn < b)).any()
        ]
        print(f"  {w}: {m.sum()}, recall {rem[ol][m].mean():.2f}; " + ", ".join(cells))


def robot(data: Path, configs: list, seed: int) -> None:
    from spectrageo.evaluate.outliers import evaluate_sequence_patterns

    ds = (("horse-gallop", "animations/horse-gallop.npz", 1),)
    for c in configs:
        rows = _with(c, lambda: evaluate_sequence_patterns(
            data, patterns=("halo",), fractions=(0.1,), datasets=ds, max_frames=12,
            seed=seed))  # fmt: skip
        rr = [r for r in rows if r["method"] == "robot"][0]
        print(f"robot horse-gallop halo 10 % seed {seed} ({c}): F1 {rr['f1']:.4f}, "
              f"theta {rr['theta_deg']:.2f}", flush=True)  # fmt: skip


def speed(data: Path, configs: list, tiles: int, repeats: int) -> None:
    from spectrageo.evaluate._outliers_scans import _inject
    from spectrageo.geometry import pca_normals

    P = next(iter(_scan_type_cases(data, {"4_6"}, fractions=(), bands=False)))[1]
    w = float(np.ptp(P[:, 0])) + 1.0
    big = np.concatenate([P + [i * w, 0.0, 0.0] for i in range(tiles)])
    Q = _inject(big, pca_normals(big, 10, orient="none"), 0.3, 0)[0]
    for name, X in (("clean", big), ("30 %", Q)):
        best: dict = {c: np.inf for c in configs}
        for _ in range(repeats):
            for c in configs:
                t0 = time.perf_counter()
                _with(c, lambda X=X: detect_outliers(X))
                best[c] = min(best[c], time.perf_counter() - t0)
        print(f"{name}, {X.shape[0]} points: "
              + ", ".join(f"{c} {v:.3f} s" for c, v in best.items()), flush=True)  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="/work/shared/data")
    ap.add_argument(
        "--task", default="outliers-scantypes", choices=("outliers", "outliers-scantypes")
    )
    ap.add_argument("--configs", default="off,on", help="off / on, comma list")
    ap.add_argument("--cases", default="", help="comma-separated scan-type case names")
    ap.add_argument("--robot", action="store_true")
    ap.add_argument("--seed", type=int, default=0, help="robot pipeline seed")
    ap.add_argument("--diagnose", action="store_true")
    ap.add_argument("--speed", action="store_true")
    ap.add_argument("--tiles", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    data, configs = Path(a.data), a.configs.split(",")
    names = set(a.cases.split(",")) if a.cases else None
    if a.diagnose:
        diagnose(data, names, configs)
    elif a.robot:
        robot(data, configs, a.seed)
    elif a.speed:
        speed(data, configs, a.tiles, a.repeats)
    else:
        cases_table(data, a.task, configs, names)


if __name__ == "__main__":
    main()
