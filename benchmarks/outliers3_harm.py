"""Do-no-harm rule of ``remove_outliers(method="rpca")`` (``static.HARM_SCORE``,
``static.HARM_SPACING``, ``static.HARM_SPREAD``, ``static.HARM_SHARE``), tuning split only.

Per tuning case of ``outliers-scantypes`` (clean scan, 10 % / 30 % injected far + near, the
1-3 / 3-5 / 5-15 spacing bands; organized frames with their grid) and, with ``--task outliers``,
of the pattern split, ``rpca`` at its defaults with each ``score:spacing:spread:share`` of ``--pairs``
(``1:0:0:0``: the rule off), or with ``--sparse-factors`` each ``RPCAOptions.sparse_factor``;
``share``: the share the scores remove. See docs/decisions.md#outliers3-harm.

    python benchmarks/outliers3_harm.py --data /work/shared/data [--task outliers-scantypes]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

import spectrageo.outliers.static as st
from spectrageo import io, noise
from spectrageo.datasets._split_outliers import OUTLIER_SCAN_TYPES
from spectrageo.evaluate._outliers_scans import (
    BANDS,
    SCAN_TYPE_CASES,
    _inject,
    _organized,
    real_labels,
    scan_path,
)
from spectrageo.evaluate.outliers import SPLIT_FRACTIONS, TUNING_SPLIT
from spectrageo.geometry import pca_normals
from spectrageo.outliers import OrganizedGrid, RPCAOptions, detect_outliers


def _f1(removed: np.ndarray, lab: np.ndarray) -> float:
    tp = np.count_nonzero(removed & lab)
    den = np.count_nonzero(removed) + np.count_nonzero(lab)
    return 2.0 * tp / den if den else 1.0


def _scan_type_cases(data: Path, names: set | None, fractions=(0.1, 0.3), bands=True):
    """``(label, cloud, labels, band or None, options)`` of the scan-type tuning cases."""
    for name, rel, split in SCAN_TYPE_CASES:
        path = scan_path(data, rel)
        if split != "tuning" or not path.exists() or (names and not any(m in name for m in names)):
            continue
        _stype, vp = OUTLIER_SCAN_TYPES[rel]
        real = real_labels(data, rel)
        shape = pixel = None
        if real is not None:
            P = real[0][~real[1]]
        else:
            pc = io.read(path, kind="points")
            P = pc.points
            shape, pixel = _organized(path, pc)
        N = pca_normals(P, 10, orient="none")

        def opts(src, vp=vp, shape=shape, pixel=pixel):
            if pixel is None:
                return RPCAOptions(viewpoint=vp)
            grid = OrganizedGrid(shape, np.where(src >= 0, pixel[np.maximum(src, 0)], -1))
            return RPCAOptions(viewpoint=vp, grid=grid)

        yield f"{name} clean", P, np.zeros(P.shape[0], bool), None, opts(np.arange(P.shape[0]))
        for frac in fractions:
            Q, lab, _, src = _inject(P, N, frac, 0)
            yield f"{name} {frac:g}", Q, lab, None, opts(src)
        if bands:
            Q, lab, band, src = _inject(P, N, 0.03, 0, bands=BANDS)
            yield f"{name} bands", Q, lab, band, opts(src)


def _pattern_cases(data: Path):
    for label, rel in TUNING_SPLIT["scans"]:
        if not (data / rel).exists():
            continue
        P = io.read(data / rel, kind="points").points
        yield f"{label} clean", P, np.zeros(P.shape[0], bool), None, RPCAOptions()
        for pat in TUNING_SPLIT["patterns"]:
            for frac in SPLIT_FRACTIONS:
                Q, lab = noise.corrupt_outliers(P, pattern=pat, fraction=frac, rng=0)
                yield f"{label} {pat} {frac:g}", Q, lab, None, RPCAOptions()


def _cell(removed, lab, band) -> str:
    if band is not None:
        rec = [removed[band == i].mean() for i in range(len(BANDS))]
        return " / ".join(f"{x:.2f}" for x in rec) + f" ({100 * removed[~lab].mean():.2f})"
    if not lab.any():
        return f"{100 * removed.mean():.2f} %"
    return f"{_f1(removed, lab):.3f} ({100 * removed[~lab].mean():.2f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="/work/shared/data")
    ap.add_argument(
        "--task", default="outliers-scantypes", choices=("outliers", "outliers-scantypes")
    )
    ap.add_argument("--pairs", default="1:0:0:0,2:1.5:3:0.03")
    ap.add_argument(
        "--sparse-factors", default="", help="sweep RPCAOptions.sparse_factor instead (e.g. 3,2)"
    )
    ap.add_argument("--fractions", default="0.1,0.3", help="injected shares (scan types)")
    ap.add_argument("--no-bands", action="store_true", help="skip the bands test (scan types)")
    ap.add_argument("--cases", default="", help="comma-separated scan-type case names")
    a = ap.parse_args()
    pairs = [tuple(float(x) for x in p.split(":")) for p in a.pairs.split(",")]
    factors = [float(f) for f in a.sparse_factors.split(",")] if a.sparse_factors else []
    if factors:  # one column per sparse factor, the rule at its defaults
        pairs = [
            (st.HARM_SCORE, st.HARM_SPACING, st.HARM_SPREAD, st.HARM_SHARE, f) for f in factors
        ]
    default = (st.HARM_SCORE, st.HARM_SPACING, st.HARM_SPREAD, st.HARM_SHARE)
    data = Path(a.data)
    names = set(a.cases.split(",")) if a.cases else None
    fr = tuple(float(f) for f in a.fractions.split(",") if f)
    if a.task == "outliers":
        cases = _pattern_cases(data)
    else:
        cases = _scan_type_cases(data, names, fr, not a.no_bands)
    print("| case | share | " + " | ".join(":".join(f"{x:g}" for x in p) for p in pairs) + " |")
    print("|---" * (len(pairs) + 2) + "|")
    f1s: dict = {p: [] for p in pairs}
    for label, Q, lab, band, opts in cases:
        r = detect_outliers(Q, options=opts)
        cells = [f"{np.mean(r.scores >= r.threshold):.4f}"]
        for p in pairs:
            st.HARM_SCORE, st.HARM_SPACING, st.HARM_SPREAD, st.HARM_SHARE = p[:4]
            o = replace(opts, sparse_factor=p[4]) if len(p) > 4 else opts
            try:
                removed = ~detect_outliers(Q, options=o).keep
            finally:
                st.HARM_SCORE, st.HARM_SPACING, st.HARM_SPREAD, st.HARM_SHARE = default
            if lab.any() and band is None:
                f1s[p].append(_f1(removed, lab))
            cells.append(_cell(removed, lab, band))
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)
    print("\nmean F1 of the contaminated cases: "
          + ", ".join(
        ":".join(f"{x:g}" for x in p) + f" {np.mean(v):.4f}" for p, v in f1s.items()
    ))  # fmt: skip


if __name__ == "__main__":
    main()
