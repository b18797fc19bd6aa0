"""Colour maps for heatmaps (jet quantised to 64 classes, as the thesis visualises)."""

from __future__ import annotations

import numpy as np


def jet(
    values, *, n_classes: int = 64, vmin: float | None = None, vmax: float | None = None
) -> np.ndarray:
    """Jet RGB colours (n, 3) uint8 in ``n_classes`` levels between ``vmin`` and ``vmax`` (default the
    finite range); non-finite values are grey.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    finite = np.isfinite(v)
    lo = float(np.min(v[finite])) if vmin is None and finite.any() else float(vmin or 0.0)
    hi = (
        float(np.max(v[finite]))
        if vmax is None and finite.any()
        else float(vmax if vmax is not None else 1.0)
    )
    span = hi - lo if hi > lo else 1.0
    t = np.clip((np.where(finite, v, lo) - lo) / span, 0.0, 1.0)
    t = np.minimum(np.floor(t * n_classes), n_classes - 1) / max(n_classes - 1, 1)
    r = np.clip(1.5 - np.abs(4.0 * t - 3.0), 0.0, 1.0)
    g = np.clip(1.5 - np.abs(4.0 * t - 2.0), 0.0, 1.0)
    b = np.clip(1.5 - np.abs(4.0 * t - 1.0), 0.0, 1.0)
    rgb = np.round(np.c_[r, g, b] * 255).astype(np.uint8)
    rgb[~finite] = 128
    return rgb
