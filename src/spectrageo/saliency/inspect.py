"""Deviation inspection of a copy against a reference model (Eq. 6.17-6.19)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from .._validation import check_positive
from ._common import check_mesh


@dataclass(frozen=True)
class Inspection:
    """Result of :func:`inspect`: per copy vertex ``deviation``, ``distance``, ``match``."""

    deviation: np.ndarray
    distance: np.ndarray
    match: np.ndarray
    saliency_reference: np.ndarray
    saliency_copy: np.ndarray

    @property
    def heat(self) -> np.ndarray:
        """``|deviation|``."""
        return np.abs(self.deviation)


def normalize_unit_box(V) -> np.ndarray:
    """Translate the bounding box to the origin and scale its largest side to 1."""
    V = np.asarray(V, dtype=np.float64)
    lo = V.min(axis=0)
    ext = float((V.max(axis=0) - lo).max())
    return (V - lo) / (ext if ext > 0 else 1.0)


def inspect(
    V_ref,
    F_ref,
    V_copy,
    F_copy,
    *,
    saliency_ref=None,
    saliency_copy=None,
    saliency_weight: float = 1.0,
    **saliency_options,
) -> Inspection:
    """Saliency deviation ``s_copy - s_ref`` of each copy vertex at its nearest ``[x, y, z, w s]``
    in the reference, both in the unit box (Eq. 6.17-6.19); the copy must have the reference pose.
    Maps default to :func:`saliency` with ``saliency_options`` (``method``, ``options``).
    """
    from .combined import saliency as _saliency

    V1, F1 = check_mesh(V_ref, F_ref, ("V_ref", "F_ref"))
    V2, F2 = check_mesh(V_copy, F_copy, ("V_copy", "F_copy"))
    w = float(check_positive(saliency_weight, "saliency_weight", allow_zero=True))

    def _map(s, V, F, name):
        if s is None:
            return _saliency(V, F, per="vertex", **saliency_options)
        s = np.asarray(s, dtype=np.float64)
        if s.shape != (V.shape[0],):
            raise InvalidInputError(f"`{name}` must have shape ({V.shape[0]},); got {s.shape}.")
        if not np.isfinite(s).all():
            raise InvalidInputError(f"`{name}` contains NaN or inf values.")
        return s

    s1 = _map(saliency_ref, V1, F1, "saliency_ref")
    s2 = _map(saliency_copy, V2, F2, "saliency_copy")
    N1, N2 = normalize_unit_box(V1), normalize_unit_box(V2)
    q1 = np.c_[N1, w * s1]
    q2 = np.c_[N2, w * s2]
    _, match = cKDTree(q1).query(q2, workers=-1)
    match = np.asarray(match, dtype=np.int64)
    dist, _ = cKDTree(N1).query(N2, workers=-1)
    return Inspection(s2 - s1[match], np.asarray(dist), match, s1, s2)


__all__ = ["Inspection", "inspect", "normalize_unit_box"]
