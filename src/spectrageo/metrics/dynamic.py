"""Metrics of mesh animations (Section 4.9): KG error, STED, per-frame static metrics; frames (T, n, 3), shared faces."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_faces, as_frames, check_positive
from .static import METRIC_KEYS, _unique_edges, compare, theta_deg
from .surface import HausdorffResult, hausdorff


def _frame_pair(frames, frames_ref) -> tuple[np.ndarray, np.ndarray]:
    A = as_frames(frames, "frames")
    B = as_frames(frames_ref, "frames_ref")
    if A.shape != B.shape:
        what = "frame counts" if A.shape[0] != B.shape[0] else "vertex counts"
        raise InvalidInputError(
            f"`frames` and `frames_ref` must have the same shape (T, n, 3); the {what} differ: "
            f"got {A.shape} and {B.shape}."
        )
    return A, B


def kg_error(frames, frames_ref) -> float:
    """KG error (percent) of Karni and Gotsman (2004), Section 4.9.

    ``100 ||A - A~||_F / ||A - E(A)||_F``, ``A`` the reference frames (3n x T), ``E(A)`` the centroids.
    """
    A_res, A_ref = _frame_pair(frames, frames_ref)
    centred = A_ref - A_ref.mean(axis=1, keepdims=True)
    den = float(np.linalg.norm(centred))
    if den == 0.0:
        raise InvalidInputError(
            "KG error is undefined: every reference frame has all its vertices at one point."
        )
    return float(100.0 * np.linalg.norm(A_res - A_ref) / den)


@dataclass(frozen=True)
class StedResult:
    """STED and its parts: ``sted = sqrt(spatial^2 + c^2 temporal^2)``."""

    sted: float
    spatial: float
    temporal: float


def _neighbourhood_edge_matrix(F: np.ndarray, n: int, E: np.ndarray, ring: int) -> sp.csr_matrix:
    """(n, e) 0/1 matrix: edge e lies in the closed ``ring``-ring of vertex v."""
    C = sp.csr_matrix(
        (np.ones(2 * len(E)), (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(n, n)
    )
    R = (sp.identity(n, format="csr") + C).astype(bool).astype(np.float64)
    Rk = R
    for _ in range(ring - 1):
        Rk = (Rk @ R).astype(bool).astype(np.float64)
    Rk = Rk.tocsc()
    M = Rk[:, E[:, 0]].multiply(Rk[:, E[:, 1]])
    return sp.csr_matrix(M)


def sted_components(
    frames, frames_ref, F, *, ring: int = 1, dt: float = 0.01, c: float = 1.0
) -> StedResult:
    """Spatio-temporal edge difference of Vasa and Skala (2011), with its parts (Section 4.9).

    Spatial: the mean over frames and vertices of the length-weighted standard deviation of the
    relative edge differences within the ``ring``-ring. Temporal: the mean relative difference of the
    edges ``sqrt(|v(t+1) - v(t)|^2 + dt^2)``, in units of the reference's bounding-box diagonal.
    ``ring``, ``dt`` and ``c`` are this package's choices (the thesis gives none).
    Returns a :class:`StedResult`.
    """
    check_positive(ring, "ring", integer=True)
    check_positive(dt, "dt")
    check_positive(c, "c", allow_zero=True)
    A, B = _frame_pair(frames, frames_ref)
    T, n, _ = B.shape
    F = as_faces(F, n, "F")
    E = _unique_edges(F, n)
    if E.shape[0] == 0:
        raise InvalidInputError("STED needs at least one non-degenerate edge in `F`.")
    M = _neighbourhood_edge_matrix(F, n, E, ring)

    sig_sum, sig_cnt = 0.0, 0
    for t in range(T):
        l_ref = np.linalg.norm(B[t, E[:, 0]] - B[t, E[:, 1]], axis=1)
        l_res = np.linalg.norm(A[t, E[:, 0]] - A[t, E[:, 1]], axis=1)
        w = l_ref
        ed = np.zeros_like(l_ref)
        np.divide(l_res - l_ref, l_ref, out=ed, where=l_ref > 0)
        shift = float(np.average(ed, weights=w)) if w.sum() > 0 else 0.0
        edc = ed - shift  # centring before the one-pass variance limits cancellation
        S0 = M @ w
        S1 = M @ (w * edc)
        S2 = M @ (w * edc * edc)
        ok = S0 > 0
        mu = S1[ok] / S0[ok]
        var = np.maximum(S2[ok] / S0[ok] - mu * mu, 0.0)
        sig_sum += float(np.sqrt(var).sum())
        sig_cnt += int(ok.sum())
    if sig_cnt == 0:
        raise InvalidInputError("STED is undefined: every reference edge has zero length.")
    spatial = sig_sum / sig_cnt

    temporal = 0.0
    if T > 1:
        diag = float(np.linalg.norm(B.reshape(-1, 3).max(axis=0) - B.reshape(-1, 3).min(axis=0)))
        if diag == 0.0:
            raise InvalidInputError("STED is undefined: the reference animation has zero extent.")
        vr = np.diff(B, axis=0) / diag
        vs = np.diff(A, axis=0) / diag
        tl_ref = np.sqrt(np.sum(vr * vr, axis=2) + dt * dt)
        tl_res = np.sqrt(np.sum(vs * vs, axis=2) + dt * dt)
        temporal = float(np.mean(np.abs(tl_res - tl_ref) / tl_ref))
    return StedResult(float(np.hypot(spatial, c * temporal)), float(spatial), temporal)


def sted(frames, frames_ref, F, *, ring: int = 1, dt: float = 0.01, c: float = 1.0) -> float:
    """STED of :func:`sted_components`."""
    return sted_components(frames, frames_ref, F, ring=ring, dt=dt, c=c).sted


def theta_per_frame(frames, frames_ref, F) -> np.ndarray:
    """Mean face-normal angle (degrees) of every frame, (T,)."""
    A, B = _frame_pair(frames, frames_ref)
    F = as_faces(F, B.shape[1], "F")
    return np.array([theta_deg(A[t], B[t], F) for t in range(A.shape[0])])


def hausdorff_per_frame(frames, frames_ref, F, *, symmetric: bool = False) -> list[HausdorffResult]:
    """:func:`hausdorff` of every frame against its reference frame."""
    A, B = _frame_pair(frames, frames_ref)
    F = as_faces(F, B.shape[1], "F")
    return [
        hausdorff(A[t], F if symmetric else None, B[t], F, symmetric=symmetric)
        for t in range(A.shape[0])
    ]


def compare_animation(
    frames,
    frames_ref,
    F=None,
    *,
    faces_result=None,
    hausdorff_distance: bool = True,
    ring: int = 1,
    dt: float = 0.01,
    c: float = 1.0,
) -> dict:
    """:func:`compare` over the frames (mean; max for ``dmax``, ``hd_max``), KG error and STED.

    ``F`` defaults to the animations' faces; ``ring``, ``dt``, ``c`` as in :func:`sted_components`.
    Adds ``theta_deg_per_frame``, ``hd_mean_per_frame``, ``nmsve_per_frame``, ``kg``, ``sted``,
    ``sted_spatial``, ``sted_temporal`` and ``n_frames``.
    """
    F_ref = getattr(frames_ref, "faces", None)
    F_res = getattr(frames, "faces", None)
    if faces_result is not None:
        F_res = faces_result
    A, B = _frame_pair(frames, frames_ref)
    if F is None:
        F = F_ref if F_ref is not None else F_res
    if F is None:
        raise InvalidInputError("`F` is required for animation metrics (shared faces).")
    F = as_faces(F, B.shape[1], "F")
    for other, name in ((F_ref, "reference faces"), (F_res, "faces_result")):
        if other is not None and (
            np.asarray(other).shape != F.shape or not np.array_equal(np.asarray(other), F)
        ):
            raise InvalidInputError(
                f"the result and the reference must share the same faces; `F` has shape {F.shape} "
                f"and {name} {np.asarray(other).shape}."
            )
    per = [compare(A[t], B[t], F, hausdorff_distance=hausdorff_distance) for t in range(len(A))]
    out: dict = {}
    for key in METRIC_KEYS:
        if key not in per[0]:
            continue
        vals = np.array([p[key] for p in per])
        out[key] = float(vals.max() if key in ("dmax", "hd_max") else vals.mean())
    out["theta_deg_per_frame"] = [p["theta_deg"] for p in per]
    if hausdorff_distance:
        out["hd_mean_per_frame"] = [p["hd_mean"] for p in per]
    out["nmsve_per_frame"] = [p["nmsve"] for p in per]
    out["kg"] = kg_error(A, B)
    s = sted_components(A, B, F, ring=ring, dt=dt, c=c)
    out["sted"] = s.sted
    out["sted_spatial"] = s.spatial
    out["sted_temporal"] = s.temporal
    out["n_frames"] = int(A.shape[0])
    return out
