"""Input checks shared by the completion functions."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .._errors import InvalidInputError
from .._validation import MAX_COORDINATE, _shape_str, coordinate_array


def as_known(known: Any, n: int, name: str = "known") -> np.ndarray:
    """A (n,) bool mask, or distinct integer indices, as a mask with at least one known vertex."""
    arr = np.asarray(known)
    if arr.dtype == bool:
        if arr.shape != (n,):
            raise InvalidInputError(
                f"`{name}` as a boolean mask must have shape ({n},); got {_shape_str(arr)}."
            )
        mask = arr.copy()
    else:
        if arr.ndim != 1 or (arr.size and arr.dtype.kind not in "iu"):
            raise InvalidInputError(
                f"`{name}` must be a boolean mask of shape ({n},) or a 1-D array of integer vertex "
                f"indices; got shape {_shape_str(arr)}, dtype {arr.dtype}."
            )
        idx = arr.astype(np.int64)
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise InvalidInputError(
                f"`{name}` has indices out of range: expected 0..{n - 1}; got {idx.min()}..{idx.max()}."
            )
        if np.unique(idx).size != idx.size:
            raise InvalidInputError(f"`{name}` contains repeated indices.")
        mask = np.zeros(n, dtype=bool)
        mask[idx] = True
    if not mask.any():
        raise InvalidInputError(f"`{name}` selects no vertex; at least one must be known.")
    return mask


def as_partial_points(V: Any, known: np.ndarray | None = None, name: str = "V") -> np.ndarray:
    """``V`` as float64 (n, 3) whose ``known`` rows (default all) are finite."""
    arr = coordinate_array(V, name, copy=True)
    if known is not None:
        rows = arr[known]
        bad = ~np.isfinite(rows).all(axis=1) | (np.abs(np.nan_to_num(rows)) > MAX_COORDINATE).any(
            axis=1
        )
        if bad.any():
            first = int(np.flatnonzero(known)[np.flatnonzero(bad)[0]])
            raise InvalidInputError(
                f"`{name}` has NaN, inf or huge coordinates at {int(bad.sum())} known vertex row(s), "
                f"first at index {first}; known vertices must have finite coordinates."
            )
    return arr


def check_components(C: sp.spmatrix, known: np.ndarray, what: str = "mesh") -> None:
    """Refuse a component of ``C`` without known vertex (its positions are undetermined)."""
    n_comp, labels = connected_components(C, directed=False)
    has = np.zeros(n_comp, dtype=bool)
    has[labels[known]] = True
    if not has.all():
        bad = np.flatnonzero(~has)
        first = int(np.flatnonzero(labels == bad[0])[0])
        raise InvalidInputError(
            f"{bad.size} connected component(s) of the {what} hold no known vertex (e.g. vertex "
            f"{first}; isolated vertices count as components); their positions are undetermined. "
            "Mark at least one vertex of each component as known."
        )
