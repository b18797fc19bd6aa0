"""The second pass on clouds of uneven spacing (``static.RESCORE_LOCAL``), tuning split only.

For every tuning case of the outlier tasks (``outliers``: the patterns of
:func:`spectrageo.noise.corrupt_outliers` at 5-30 %; ``outliers-scantypes``: 10 / 30 / 40 %
injected far + near), ``rpca`` at its defaults against the same run with ``RESCORE_LOCAL`` in
``--factors`` (``inf``: the previous behaviour, no second pass above ``RESCORE_SPREAD``). A case
whose first pass does not take the ``"local"`` second pass is the same at every factor and is
counted, not re-run. See docs/decisions.md#outliers-lidar-local-rescore.

    python benchmarks/outliers_lidar_local_rescore.py --data /work/shared/data [--task outliers]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import spectrageo.outliers.static as st
from spectrageo import io, noise
from spectrageo.datasets._split_outliers import OUTLIER_SCAN_TYPES
from spectrageo.evaluate._outliers_scans import SCAN_TYPE_CASES, _inject, real_labels, scan_path
from spectrageo.evaluate.outliers import SPLIT_FRACTIONS, TUNING_SPLIT
from spectrageo.geometry import pca_normals
from spectrageo.outliers import RPCAOptions, detect_outliers


def _f1(removed: np.ndarray, lab: np.ndarray) -> float:
    tp = np.count_nonzero(removed & lab)
    den = np.count_nonzero(removed) + np.count_nonzero(lab)
    return 2.0 * tp / den if den else 1.0


def _cases(data: Path, task: str):
    """``(label, cloud, labels, viewpoint)`` of the tuning cases of ``task``."""
    if task == "outliers":
        for label, rel in TUNING_SPLIT["scans"]:
            if not (data / rel).exists():
                continue
            P = io.read(data / rel, kind="points").points
            yield f"{label} clean", P, np.zeros(P.shape[0], bool), None
            for pat in TUNING_SPLIT["patterns"]:
                for frac in SPLIT_FRACTIONS:
                    Q, lab = noise.corrupt_outliers(P, pattern=pat, fraction=frac, rng=0)
                    yield f"{label} {pat} {frac:g}", Q, lab, None
        return
    for name, rel, split in SCAN_TYPE_CASES:
        stype, vp = OUTLIER_SCAN_TYPES[rel]
        path = scan_path(data, rel)
        if split != "tuning" or stype == "Kinect organized frame" or not path.exists():
            continue
        real = real_labels(data, rel)
        P = real[0][~real[1]] if real is not None else io.read(path, kind="points").points
        N = pca_normals(P, 10, orient="none")
        yield f"{name} clean", P, np.zeros(P.shape[0], bool), vp
        for frac in (0.1, 0.3, 0.4):
            Q, lab, _, _ = _inject(P, N, frac, 0)
            yield f"{name} {frac:g}", Q, lab, vp


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="/work/shared/data")
    ap.add_argument("--task", default="outliers", choices=("outliers", "outliers-scantypes"))
    ap.add_argument("--factors", default="inf,1.5,2,2.5")
    a = ap.parse_args()
    factors = [float(f) for f in a.factors.split(",")]
    default = st.RESCORE_LOCAL
    print(
        "| case | removed | spread | "
        + " | ".join(f"F1 (clean FP %) at {f:g}" for f in factors)
        + " |"
    )
    print("|---" * (len(factors) + 3) + "|")
    same = 0
    means = {f: [] for f in factors}
    for label, Q, lab, vp in _cases(Path(a.data), a.task):
        r = detect_outliers(Q, options=RPCAOptions(viewpoint=vp))
        if not r.info.get("rescore", {}).get("local"):
            same += 1
            for f in factors:
                if lab.any():
                    means[f].append(_f1(~r.keep, lab))
            continue
        cells = []
        for f in factors:
            st.RESCORE_LOCAL = f
            try:
                rf = detect_outliers(Q, options=RPCAOptions(viewpoint=vp))
            finally:
                st.RESCORE_LOCAL = default
            f1 = _f1(~rf.keep, lab)
            if lab.any():
                means[f].append(f1)
            cells.append(f"{f1:.3f} ({100 * np.mean(~rf.keep[~lab]):.2f})")
        share = float(np.mean(~r.keep))
        spread = r.info["rescore_spread"]
        print(f"| {label} | {share:.3f} | {spread:.3f} | " + " | ".join(cells) + " |", flush=True)
    mean = ", ".join(f"{f:g}: {np.mean(v):.4f}" for f, v in means.items())
    print(f"\n{same} cases without the local second pass (the same at every factor); mean F1 of "
          f"the contaminated cases: {mean}")  # fmt: skip


if __name__ == "__main__":
    main()
