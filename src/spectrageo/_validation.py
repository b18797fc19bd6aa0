"""Input checks at the public boundary; errors name the argument, the expected and the received value."""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np

from ._errors import InvalidInputError


def _shape_str(a: Any) -> str:
    shape = getattr(a, "shape", None)
    return str(tuple(shape)) if shape is not None else type(a).__name__


#: Largest coordinate magnitude accepted by :func:`as_points`: squared distances and cross products
#: of coordinates up to 1e150 stay below the float64 maximum (1.8e308), so no kernel overflows to
#: inf (an inf turned into an index by compiled code would read or write out of bounds).
MAX_COORDINATE = 1e150
#: Smallest non-zero extent (largest side of the bounding box) accepted by :func:`as_points`:
#: areas and Gram determinants (fourth powers of lengths) of a smaller point set underflow to
#: zero in float64, so every triangle would look degenerate and every length scale vanish.
MIN_EXTENT = 1e-70


def coordinate_array(
    X: Any, name: str, *, ndim: int = 2, copy: bool = False, allow_empty: bool = False
) -> np.ndarray:
    """``X`` as float64 (n, 3) or (T, n, 3), checked for type, shape and emptiness only."""
    want = "(n, 3)" if ndim == 2 else "(T, n, 3)"
    try:
        arr = np.array(X, dtype=np.float64) if copy else np.asarray(X, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(
            f"`{name}` must be a numeric array of shape {want}; got {type(X).__name__}."
        ) from exc
    if arr.ndim != ndim or arr.shape[-1] != 3:
        raise InvalidInputError(f"`{name}` must have shape {want}; got {_shape_str(arr)}.")
    if arr.size == 0 and not allow_empty:
        raise InvalidInputError(
            f"`{name}` is empty; at least one point is required; got shape {arr.shape}."
        )
    return arr


def as_points(
    V: Any, name: str = "V", *, allow_empty: bool = False, copy: bool = False
) -> np.ndarray:
    """``V`` as C-contiguous float64 (n, 3), finite, within :data:`MAX_COORDINATE` and spanning
    nothing or at least :data:`MIN_EXTENT`.
    """
    arr = coordinate_array(V, name, copy=copy, allow_empty=allow_empty)
    if not arr.size:
        return np.ascontiguousarray(arr)
    # one min and one max per column serve all three checks (NaN and inf propagate into them),
    # with no full-size temporary; the rows are searched only to name a bad one in the error.
    # (Column by column: numpy's axis-0 reduction of an (n, 3) array is about 10x slower.)
    lo = np.array([arr[:, j].min() for j in range(3)])
    hi = np.array([arr[:, j].max() for j in range(3)])
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
        raise InvalidInputError(
            f"`{name}` contains NaN or inf coordinates at {bad.size} row(s), first at index {int(bad[0])}."
        )
    if max(-float(lo.min()), float(hi.max())) > MAX_COORDINATE:
        big = np.flatnonzero((np.abs(arr) > MAX_COORDINATE).any(axis=1))
        raise InvalidInputError(
            f"`{name}` has coordinates of magnitude above {MAX_COORDINATE:g} at {big.size} row(s), "
            f"first at index {int(big[0])} ({float(np.abs(arr[big[0]]).max()):.3g}); squared "
            "distances would overflow. Rescale the data."
        )
    extent = float((hi - lo).max())
    if 0.0 < extent < MIN_EXTENT:
        raise InvalidInputError(
            f"`{name}` spans only {extent:.3g} (bounding box); lengths that small underflow "
            f"in areas and squared distances (below {MIN_EXTENT:g}). Rescale the data."
        )
    return np.ascontiguousarray(arr)


def as_faces(F: Any, n_vertices: int, name: str = "F", *, allow_empty: bool = False) -> np.ndarray:
    """Return ``F`` as a C-contiguous int64 array of shape (m, 3) with indices in ``[0, n_vertices)``."""
    arr = np.asarray(F)
    if arr.size == 0 and arr.ndim <= 2:
        arr = arr.reshape(0, 3)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InvalidInputError(f"`{name}` must have shape (m, 3); got {_shape_str(arr)}.")
    if arr.dtype.kind == "f":
        if not np.isfinite(arr).all() or np.any(arr != np.round(arr)):
            raise InvalidInputError(
                f"`{name}` must hold integer vertex indices; got non-integer values."
            )
    elif arr.dtype.kind not in "iu":
        raise InvalidInputError(
            f"`{name}` must hold integer vertex indices; got dtype {arr.dtype}."
        )
    if arr.shape[0] == 0 and not allow_empty:
        raise InvalidInputError(f"`{name}` is empty; a mesh needs at least one face.")
    if arr.size:
        # in the original dtype: a uint64 index >= 2**63 must not wrap to a negative int64
        lo, hi = int(arr.min()), int(arr.max())
        if lo < 0 or hi >= n_vertices:
            raise InvalidInputError(
                f"`{name}` has vertex indices out of range: expected 0..{n_vertices - 1}; got {lo}..{hi}."
            )
    return np.ascontiguousarray(arr, dtype=np.int64)


def as_scalar_field(x: Any, n: int, name: str) -> np.ndarray:
    """Return ``x`` as a float64 vector of length ``n`` with finite values."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != (n,):
        raise InvalidInputError(f"`{name}` must have shape ({n},); got {_shape_str(arr)}.")
    if not np.isfinite(arr).all():
        raise InvalidInputError(f"`{name}` contains NaN or inf values.")
    return arr


def check_positive(
    value: Any, name: str, *, integer: bool = False, allow_zero: bool = False
) -> Any:
    """Check that ``value`` is a (strictly, unless ``allow_zero``) positive finite number."""
    ok_type = (int, np.integer) if integer else (int, float, np.integer, np.floating)
    if isinstance(value, bool) or not isinstance(value, ok_type):
        kind = "an integer" if integer else "a number"
        raise InvalidInputError(f"`{name}` must be {kind}; got {value!r}.")
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise InvalidInputError(f"`{name}` must be {bound}; got {value!r}.")
    return value


def check_choice(value: Any, name: str, choices: tuple[str, ...] | list[str]) -> str:
    """Check that ``value`` is one of ``choices``."""
    if value not in choices:
        raise InvalidInputError(
            f"`{name}` must be one of {', '.join(map(repr, choices))}; got {value!r}."
        )
    return value


def as_rng(rng: Any) -> np.random.Generator:
    """A :class:`numpy.random.Generator` from a seed, a Generator or None (seed 0, reproducible)."""
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None:
        return np.random.default_rng(0)
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        if rng < 0:
            raise InvalidInputError(f"`rng` seed must be a non-negative integer; got {int(rng)}.")
        return np.random.default_rng(int(rng))
    raise InvalidInputError(
        f"`rng` must be an int seed, a numpy Generator or None; got {type(rng).__name__}."
    )


def as_frames(frames: Any, name: str = "frames") -> np.ndarray:
    """Animation frames (T, n, 3) float64 (or ``.frames``), finite and at most
    :data:`MAX_COORDINATE`; the first bad vertex is named.
    """
    A = coordinate_array(getattr(frames, "frames", frames), name, ndim=3)
    if not np.isfinite(A).all():
        bad = np.argwhere(~np.isfinite(A).all(axis=2))[0]
        raise InvalidInputError(
            f"`{name}` contains NaN or inf coordinates (first at frame {bad[0]}, vertex {bad[1]})."
        )
    if np.abs(A).max() > MAX_COORDINATE:
        bad = np.argwhere((np.abs(A) > MAX_COORDINATE).any(axis=2))[0]
        raise InvalidInputError(
            f"`{name}` has coordinates of magnitude above {MAX_COORDINATE:g} (first at frame "
            f"{bad[0]}, vertex {bad[1]}); squared distances would overflow. Rescale the data."
        )
    return A


def options_with_legacy(options: Any, legacy: dict, cls: type, func: str) -> Any:
    """``options`` (a ``cls`` or None) with the deprecated keywords ``legacy`` of ``func``
    mapped onto its fields, with a :class:`DeprecationWarning`; :class:`TypeError` for an unknown one.
    """
    if options is None:
        options = cls()
    elif not isinstance(options, cls):
        raise InvalidInputError(
            f"`options` must be a {cls.__name__} or None; got {type(options).__name__}."
        )
    if not legacy:
        return options
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(legacy) - names)
    if unknown:
        raise TypeError(f"{func}() got an unexpected keyword argument {unknown[0]!r}")
    given = ", ".join(f"{k}=..." for k in sorted(legacy))
    warnings.warn(
        f"{func}(): passing {', '.join(sorted(legacy))} as keyword arguments is deprecated; "
        f"use options={cls.__name__}({given}).",
        DeprecationWarning,
        stacklevel=3,
    )
    return dataclasses.replace(options, **legacy)


def deprecated_flag(func: str, flag: str, replacement: str) -> None:
    """:class:`DeprecationWarning` for the return-shape flag ``flag`` of ``func``, naming ``replacement``."""
    warnings.warn(
        f"{func}({flag}=...) is deprecated; use {replacement} instead.",
        DeprecationWarning,
        stacklevel=3,
    )
