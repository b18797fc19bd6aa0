"""Automatic thresholds of outlier scores (Otsu, density and valley rules)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import check_choice

__all__ = ["auto_threshold", "valley_threshold"]

#: Smallest automatic RPCA threshold, in units of the point spacing (see :func:`auto_threshold`);
#: chosen on the tuning split; see docs/decisions.md#outlier-rpca-constants.
RPCA_MIN_TAU = 0.5
#: Automatic threshold rules of :func:`remove_outliers`; ``"valley"`` (:func:`valley_threshold`)
#: is the RPCA default, ``"density"`` and ``"otsu"`` the rules of :func:`auto_threshold`.
THRESHOLD_RULES = ("valley", "density", "otsu")
#: The automatic RPCA threshold rule of :func:`remove_outliers` (and of the tiled runs).
DEFAULT_THRESHOLD_RULE = "valley"
#: Constants of the ``"valley"`` rule, chosen on the tuning split of
#: :data:`spectrageo.evaluate.outliers.TUNING_SPLIT` only (see :func:`valley_threshold`).
VALLEY_BIN = 0.05  # histogram bin width, decades of the score
VALLEY_SMOOTH = 1.0  # Gaussian smoothing of the histogram, in bins
VALLEY_RATIO = 1.05  # the density must rise by this factor after the valley ...
VALLEY_Z = 3.0  # ... and by this many standard deviations of the smoothed count


def auto_threshold(scores: Any, *, minimum: float = 0.0, rule: str = "otsu") -> float:
    """Automatic threshold: Otsu's two-class split of ``log(1 + score)``, at least ``minimum``.

    ``rule="density"`` moves the Otsu split ``t0`` down to the first bin (``10 / d`` wide) in
    ``[0, t0)`` whose density is at most ``2 d``, ``d`` the (flat) score density in ``[t0, 2 t0)``:
    where the inlier density meets the outlier density. ``rule="valley"`` is the threshold of
    :func:`valley_threshold`. See docs/decisions.md#outliers-threshold-rules.

    Parameters
    ----------
    scores : (n,) array_like
        Outlier scores (non-finite values are ignored).
    minimum : float
        Lower bound of the threshold.
    rule : {"otsu", "density", "valley"}

    Returns
    -------
    float
    """
    check_choice(rule, "rule", THRESHOLD_RULES)
    if rule == "valley":
        return valley_threshold(scores, minimum=minimum)[0]
    s = np.asarray(scores, dtype=np.float64)
    s = s[np.isfinite(s)]
    if s.size == 0:
        return float(minimum)
    t0 = _otsu_log1p(s, float(minimum))
    if rule == "otsu" or t0 <= 0.0:
        return t0
    d = np.count_nonzero((s >= t0) & (s < 2.0 * t0)) / t0
    if d <= 0.0:
        return t0
    w = 10.0 / d
    edges = np.arange(0.0, t0 + w, w)
    if edges.size < 2:
        return t0
    counts = _bin_counts(s, edges)
    low = np.flatnonzero(counts <= 2.0 * d * w)
    if low.size == 0:
        return t0
    return float(max(edges[low[0]], minimum))


def _bin_counts(s: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """``np.histogram(s, edges)[0]`` (last bin closed) without sorting ``s``."""
    b = np.searchsorted(edges, s, side="right") - 1
    b[s == edges[-1]] = edges.size - 2
    return np.bincount(b[(b >= 0) & (b < edges.size - 1)], minlength=edges.size - 1)


def valley_threshold(scores: Any, *, minimum: float = RPCA_MIN_TAU) -> tuple[float, dict]:
    r"""Threshold at the valley between the inlier and the outlier populations of the scores.

    With ``d`` the histogram of ``x = log10(score)`` (bins of :data:`VALLEY_BIN` decades, Gaussian
    smoothing of :data:`VALLEY_SMOOTH` bins) and ``m`` the inlier mode, walk up from ``m`` (or from
    the bin of ``minimum``) keeping the lowest bin ``v``; the first bin ``j`` with

    .. math::

        d_j \ge \rho\, d_v \quad\text{and}\quad
        d_j - d_v \ge z \sqrt{(d_v + 1) / (2 \sqrt{\pi}\, g)}

    marks a valley at ``v`` and ``tau = max(min(10^{x_v}, tau_d), minimum)``, ``tau_d`` the
    ``"density"`` rule of :func:`auto_threshold` (without a valley ``max(tau_d, minimum)``).
    Constants chosen on the tuning split; see docs/decisions.md#outliers-threshold-rules.

    Parameters
    ----------
    scores : (n,) array_like
        Outlier scores (non-finite values are ignored).
    minimum : float
        Lower bound ``tau_min``.

    Returns
    -------
    threshold : float
    info : dict
        ``contamination`` (share of scores at or above the threshold), ``valley``, ``tau_density``.
    """
    s = np.asarray(scores, dtype=np.float64)
    s = s[np.isfinite(s)]
    if s.size == 0:
        return float(minimum), {"contamination": 0.0, "valley": None, "tau_density": None}
    tau_d = auto_threshold(s, minimum=minimum, rule="density")
    valley = _log_valley(s[s > 0], float(minimum))
    tau = tau_d if valley is None else max(min(valley, tau_d), float(minimum))
    info = {
        "contamination": float(np.count_nonzero(s >= tau) / s.size),
        "valley": valley,
        "tau_density": tau_d,
    }
    return float(tau), info


def _log_valley(p: np.ndarray, floor: float = 0.0) -> float | None:
    """The valley of :func:`valley_threshold` (in score units, at or above ``floor``), or None."""
    from scipy.ndimage import gaussian_filter1d

    if p.size < 10:
        return None
    x = np.log10(p)
    lo, hi = float(np.quantile(x, 0.001)), float(x.max())
    nb = max(int(np.ceil((hi - lo) / VALLEY_BIN)), 3)
    h, edges = np.histogram(x, bins=nb, range=(lo, lo + nb * VALLEY_BIN))
    d = gaussian_filter1d(h.astype(np.float64), VALLEY_SMOOTH, mode="constant")
    below = np.flatnonzero(edges[:-1] <= np.median(x))
    mode = int(below[np.argmax(d[below])])
    noise = 1.0 / (2.0 * np.sqrt(np.pi) * VALLEY_SMOOTH)
    if floor > 0.0:  # a valley below the floor cannot give the threshold: start the walk there
        mode = max(mode, min(int(np.searchsorted(edges, np.log10(floor))), nb - 1))
    v = mode
    for j in range(mode + 1, nb):
        if d[j] < d[v]:
            v = j
        elif d[j] >= VALLEY_RATIO * d[v] and d[j] - d[v] >= VALLEY_Z * np.sqrt(noise * (d[v] + 1)):
            return float(10.0 ** (0.5 * (edges[v] + edges[v + 1])))
    return None


def _otsu_log1p(s: np.ndarray, minimum: float) -> float:
    x = np.log1p(np.maximum(s, 0.0))
    lo, hi = float(x.min()), float(x.max())
    if hi <= lo:
        return float(max(np.expm1(hi), minimum))
    h, edges = np.histogram(x, bins=256, range=(lo, hi))
    c = 0.5 * (edges[1:] + edges[:-1])
    w0 = np.cumsum(h).astype(np.float64)
    m0 = np.cumsum(h * c)
    W, M = w0[-1], m0[-1]
    w1 = W - w0
    ok = (w0 > 0) & (w1 > 0)
    between = np.zeros_like(c)
    between[ok] = (M * w0[ok] / W - m0[ok]) ** 2 / (w0[ok] * w1[ok])
    # threshold at the upper edge of the lower class
    t = float(np.expm1(edges[int(np.argmax(between)) + 1]))
    return float(max(t, minimum))
