"""The second pass of the RPCA outlier removal against the first-pass removed share (tuning split).

For each scan-type tuning scan without an image grid (task ``outliers-scantypes``: the five laser
range scans, Kinect milk, cloud_bin_0) and each injected fraction (the scan-type mix: half
uniform in the padded box, half 5-15 spacings along the normals, seed 0), prints the share the
first pass removes and the F1 with the second pass off and always on. ``RESCORE_SHARE`` is put
between the largest share at which the second pass does not help and the smallest at which it
helps on every scan (docs/decisions.md#outliers-rescore). The spread gate (``RESCORE_SPREAD``)
applies in both runs; these scans pass it.

    python benchmarks/outliers_rescore_sweep.py [--fractions 0.05,0.1,0.15,0.2,0.25,0.3,0.4]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from spectrageo.datasets._split_outliers import OUTLIER_SCAN_TYPES
from spectrageo.evaluate._outliers_scans import SCAN_TYPE_CASES, _inject, real_labels


def _f1(removed: np.ndarray, lab: np.ndarray) -> float:
    tp = np.count_nonzero(removed & lab)
    return 2 * tp / max(np.count_nonzero(removed) + np.count_nonzero(lab), 1)


def main() -> None:
    from spectrageo import io
    from spectrageo.geometry import pca_normals
    from spectrageo.outliers import RPCAOptions, detect_outliers

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="/work/shared/data")
    ap.add_argument("--fractions", default="0.05,0.1,0.15,0.2,0.25,0.3,0.4")
    a = ap.parse_args()
    data = Path(a.data)
    fractions = [float(f) for f in a.fractions.split(",")]
    print("| scan | " + " | ".join(f"{100 * f:g} %: share, F1 off -> on" for f in fractions) + " |")
    print("|---" * (len(fractions) + 1) + "|")
    for name, rel, split in SCAN_TYPE_CASES:
        stype, vp = OUTLIER_SCAN_TYPES[rel]
        if split != "tuning" or stype == "Kinect organized frame" or not (data / rel).exists():
            continue
        real = real_labels(data, rel)
        P = real[0][~real[1]] if real is not None else io.read(data / rel, kind="points").points
        N = pca_normals(P, 10, orient="none")
        cells = []
        for frac in fractions:
            Q, lab, _, _ = _inject(P, N, frac, 0)
            off = detect_outliers(Q, options=RPCAOptions(viewpoint=vp, rescore_share=None))
            on = detect_outliers(Q, options=RPCAOptions(viewpoint=vp, rescore_share=1e-9))
            share = 1.0 - float(off.keep.mean())
            cells.append(f"{share:.3f}, {_f1(~off.keep, lab):.3f} -> {_f1(~on.keep, lab):.3f}")
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
