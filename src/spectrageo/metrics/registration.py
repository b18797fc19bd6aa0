"""Registration errors (Eq. 4.34-4.35) and bit rates."""

from __future__ import annotations

import numpy as np

from .._errors import InvalidInputError
from .._validation import check_positive


def _matrix(R, name: str) -> np.ndarray:
    try:
        a = np.asarray(R, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"`{name}` must be a numeric (3, 3) or (4, 4) matrix.") from exc
    if a.shape == (4, 4):
        a = a[:3, :3]
    if a.shape != (3, 3):
        raise InvalidInputError(f"`{name}` must have shape (3, 3) or (4, 4); got {a.shape}.")
    if not np.isfinite(a).all():
        raise InvalidInputError(f"`{name}` contains NaN or inf values.")
    return a


def rotation_error_deg(R, R_gt) -> float:
    """Rotation error (Eq. 4.34) in [0, 180] degrees of (3, 3) or (4, 4) ``R`` against ``R_gt``."""
    R = _matrix(R, "R")
    R_gt = _matrix(R_gt, "R_gt")
    if abs(np.linalg.det(R_gt)) < 1e-12:
        raise InvalidInputError("`R_gt` is singular; a rotation matrix is expected.")
    M = np.linalg.solve(R_gt.T, R.T).T  # R @ inv(R_gt)
    arg = np.clip((np.trace(M) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(arg)))


def translation_error(t, t_gt) -> float:
    """Translation error (Eq. 4.35) ``||t - t_gt||`` of 3-vectors or (4, 4) transforms."""
    vals = []
    for x, name in ((t, "t"), (t_gt, "t_gt")):
        a = np.asarray(x, dtype=np.float64)
        if a.shape == (4, 4):
            a = a[:3, 3]
        a = a.reshape(-1) if a.shape in ((3, 1), (1, 3)) else a
        if a.shape != (3,):
            raise InvalidInputError(
                f"`{name}` must be a 3-vector or a (4, 4) transform; got shape {a.shape}."
            )
        if not np.isfinite(a).all():
            raise InvalidInputError(f"`{name}` contains NaN or inf values.")
        vals.append(a)
    return float(np.linalg.norm(vals[0] - vals[1]))


def bits_per_vertex(
    n_bits: float | None = None,
    n_vertices: int | None = None,
    n_frames: int = 1,
    *,
    n_bytes: float | None = None,
) -> float:
    """``n_bits / (n_vertices n_frames)`` (bpv, bpvf); exactly one of ``n_bits`` and ``n_bytes``."""
    if (n_bits is None) == (n_bytes is None):
        raise InvalidInputError("give exactly one of `n_bits` and `n_bytes`.")
    if n_vertices is None:
        raise InvalidInputError("`n_vertices` is required.")
    check_positive(n_vertices, "n_vertices", integer=True)
    check_positive(n_frames, "n_frames", integer=True)
    if n_bits is None:
        check_positive(n_bytes, "n_bytes", allow_zero=True)
        n_bits = 8.0 * float(n_bytes)
    else:
        check_positive(n_bits, "n_bits", allow_zero=True)
    return float(n_bits) / (int(n_vertices) * int(n_frames))
