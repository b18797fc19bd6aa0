"""Metrics between a result and a reference with the same vertex order (Section 4.9), model units.

Faces or vertices with a zero normal in either mesh are left out; none left raises InvalidInputError.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_choice
from ..geometry.data import Mesh
from ..geometry.primitives import edges, face_normals, vertex_normals
from .surface import _Side, _symmetric

METRIC_KEYS = ("theta_deg", "dmean", "dmax", "dist_n", "dmean_n", "nmsve", "hd_mean", "hd_max")


# --------------------------------------------------------------------------- validation
def _pair(V, V_ref, names=("V", "V_ref")) -> tuple[np.ndarray, np.ndarray]:
    V = as_points(V, names[0])
    V_ref = as_points(V_ref, names[1])
    if V.shape != V_ref.shape:
        raise InvalidInputError(
            f"`{names[0]}` and `{names[1]}` must have the same number of vertices (vertex i of one "
            f"corresponds to vertex i of the other); got shapes {V.shape} and {V_ref.shape}."
        )
    return V, V_ref


def _pair_faces(V, V_ref, F) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    V, V_ref = _pair(V, V_ref)
    return V, V_ref, as_faces(F, V.shape[0], "F")


def _angles_deg(N1: np.ndarray, N2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Angles (degrees) between rows, by ``atan2(|a x b|, a . b)``, and the mask of non-zero pairs."""
    valid = _valid_rows(N1) & _valid_rows(N2)
    cross = np.linalg.norm(np.cross(N1, N2), axis=1)
    dot = np.einsum("ij,ij->i", N1, N2)
    ang = np.degrees(np.arctan2(cross, dot))
    ang[~valid] = 0.0
    return ang, valid


def _unique_edges(F: np.ndarray, n: int) -> np.ndarray:
    """Unique undirected edges (i < j) of ``F``, shape (e, 2)."""
    return edges(F)


def _valid_rows(N: np.ndarray) -> np.ndarray:
    return np.abs(N).sum(axis=1) > 0


# --------------------------------------------------------------------------- normals
def face_angle_errors(V, V_ref, F) -> np.ndarray:
    """Angle (degrees) between corresponding face normals, (m,); 0 on degenerate faces."""
    V, V_ref, F = _pair_faces(V, V_ref, F)
    return _angles_deg(face_normals(V, F), face_normals(V_ref, F))[0]


def theta_deg(V, V_ref, F) -> float:
    """Mean angle (degrees) between the face normals (Eq. 3.2) of ``(V, F)`` and ``(V_ref, F)`` (Section 4.9)."""
    V, V_ref, F = _pair_faces(V, V_ref, F)
    return _theta(face_normals(V, F), face_normals(V_ref, F))


def _theta(N: np.ndarray, Nr: np.ndarray) -> float:
    ang, valid = _angles_deg(N, Nr)
    if not valid.any():
        raise InvalidInputError(
            "theta is undefined: every face is degenerate (zero area) in the result or the reference."
        )
    return float(ang[valid].mean())


def vertex_normal_errors(V, V_ref, F) -> np.ndarray:
    """``||n_i - n_i_ref||`` between unit vertex normals (Eq. 3.3), (n,); 0 where undefined."""
    V, V_ref, F = _pair_faces(V, V_ref, F)
    N, Nr = vertex_normals(V, F), vertex_normals(V_ref, F)
    valid = _valid_rows(N) & _valid_rows(Nr)
    err = np.linalg.norm(N - Nr, axis=1)
    err[~valid] = 0.0
    return err


def dist_n(V, V_ref, F) -> float:
    """Mean ``||n_i - n_i_ref||`` over vertices of the unit vertex normals (Eq. 3.3, Section 4.9), in [0, 2]."""
    V, V_ref, F = _pair_faces(V, V_ref, F)
    return _dist_n(vertex_normals(V, F), vertex_normals(V_ref, F))


def _dist_n(N: np.ndarray, Nr: np.ndarray) -> float:
    valid = _valid_rows(N) & _valid_rows(Nr)
    if not valid.any():
        raise InvalidInputError(
            "dist_n is undefined: no vertex has a non-zero normal in both meshes."
        )
    return float(np.linalg.norm(N[valid] - Nr[valid], axis=1).mean())


def dmean_n(V, V_ref, F) -> float:
    """Mean ``||f_j - f_j_ref||`` between unit face normals (Section 4.9), in [0, 2]."""
    V, V_ref, F = _pair_faces(V, V_ref, F)
    return _dmean_n(face_normals(V, F), face_normals(V_ref, F))


def _dmean_n(N: np.ndarray, Nr: np.ndarray) -> float:
    valid = _valid_rows(N) & _valid_rows(Nr)
    if not valid.any():
        raise InvalidInputError(
            "dmean_n is undefined: every face is degenerate (zero area) in the result or the reference."
        )
    return float(np.linalg.norm(N[valid] - Nr[valid], axis=1).mean())


# --------------------------------------------------------------------------- positions
def vertex_errors(V, V_ref) -> np.ndarray:
    """``|v_i - v_i_ref|`` per vertex (n,), the heatmap of Section 4.9."""
    V, V_ref = _pair(V, V_ref)
    return np.linalg.norm(V - V_ref, axis=1)


def dmean(V, V_ref) -> float:
    """Dmean d: mean distance between corresponding vertices (Section 4.9)."""
    return float(vertex_errors(V, V_ref).mean())


def dmax(V, V_ref) -> float:
    """Dmax d: largest distance between corresponding vertices (Section 4.9)."""
    return float(vertex_errors(V, V_ref).max())


def _gl(V: np.ndarray, E: np.ndarray) -> np.ndarray:
    """Geometric Laplacian of Eq. (4.33) with inverse edge lengths (zero-length edges: the largest weight)."""
    n = V.shape[0]
    d = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    w = np.zeros_like(d)
    pos = d > 0
    w[pos] = 1.0 / d[pos]
    if (~pos).any():
        w[~pos] = w.max() if pos.any() else 1.0
    rows = np.concatenate([E[:, 0], E[:, 1]])
    cols = np.concatenate([E[:, 1], E[:, 0]])
    ww = np.concatenate([w, w])
    s = np.bincount(rows, weights=ww, minlength=n)
    wv = np.stack([np.bincount(rows, weights=ww * V[cols, j], minlength=n) for j in range(3)], 1)
    avg = np.zeros_like(V)
    np.divide(wv, s[:, None], out=avg, where=s[:, None] > 0)
    out = V - avg
    out[s == 0] = 0.0
    return out


def nmsve(V, V_ref, F, *, normalize: str = "bbox") -> float:
    """Normalised mean square visual error (Eqs. 4.32-4.33, Karni and Gotsman).

    ``1/(2n) sum_i (||v_i - v~_i||^2 + ||GL(v_i) - GL(v~_i)||^2) / s^2``, ``s`` the reference's
    bounding-box diagonal (``normalize="bbox"``) or 1; see docs/decisions.md#metrics-nmsve.
    """
    check_choice(normalize, "normalize", ("bbox", "none"))
    V, V_ref, F = _pair_faces(V, V_ref, F)
    return _nmsve(V, V_ref, _unique_edges(F, V.shape[0]), normalize)


def _nmsve(V: np.ndarray, V_ref: np.ndarray, E: np.ndarray, normalize: str) -> float:
    n = V.shape[0]
    e1 = np.sum((V - V_ref) ** 2)
    e2 = np.sum((_gl(V, E) - _gl(V_ref, E)) ** 2)
    val = (e1 + e2) / (2.0 * n)
    if normalize == "bbox":
        diag = float(np.linalg.norm(V_ref.max(axis=0) - V_ref.min(axis=0)))
        if diag == 0.0:
            raise InvalidInputError(
                "nmsve with normalize='bbox' needs a reference of non-zero extent; all reference "
                "vertices coincide."
            )
        val /= diag**2
    return float(val)


# --------------------------------------------------------------------------- all at once
def _unpack(obj: Any, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    if isinstance(obj, Mesh):
        return obj.vertices, obj.faces
    if hasattr(obj, "points") and not hasattr(obj, "faces"):
        raise InvalidInputError(f"`{name}` must be a mesh or an (n, 3) array; got a point cloud.")
    return as_points(obj, name), None


def compare(
    result,
    reference,
    F=None,
    *,
    faces_result=None,
    hausdorff_distance: bool = True,
) -> dict[str, float]:
    """All static metrics of Section 4.9 between a result and its reference (same vertex order).

    Parameters
    ----------
    result, reference : Mesh or (n, 3) array_like
    F : (m, 3) array_like of int, optional
        Shared faces (default: those of ``reference``, then ``result``); ``faces_result`` must equal it.
    hausdorff_distance : bool
        Compute ``hd_mean`` and ``hd_max`` as :func:`compare_surfaces` does (the costliest part).

    Returns
    -------
    dict
        The :data:`METRIC_KEYS` (``theta_deg`` in degrees).
    """
    V, F_res = _unpack(result, "result")
    V_ref, F_ref = _unpack(reference, "reference")
    if faces_result is not None:
        F_res = faces_result
    if F is None:
        F = F_ref if F_ref is not None else F_res
    if F is None:
        raise InvalidInputError(
            "`F` is required when neither `result` nor `reference` is a Mesh (metrics need faces)."
        )
    V, V_ref = _pair(V, V_ref, names=("result", "reference"))
    F = as_faces(F, V.shape[0], "F")
    for other, name in ((F_ref, "reference faces"), (F_res, "faces_result")):
        if other is None:
            continue
        other = np.asarray(other)
        if other.shape != F.shape or not np.array_equal(other, F):
            raise InvalidInputError(
                f"the result and the reference must share the same faces; `F` has shape {F.shape} "
                f"and {name} {other.shape}{' with different indices' if other.shape == F.shape else ''}."
            )
    FN, FNr = face_normals(V, F), face_normals(V_ref, F)
    err = np.linalg.norm(V - V_ref, axis=1)
    out = {
        "theta_deg": _theta(FN, FNr),
        "dmean": float(err.mean()),
        "dmax": float(err.max()),
        "dist_n": _dist_n(vertex_normals(V, F), vertex_normals(V_ref, F)),
        "dmean_n": _dmean_n(FN, FNr),
        "nmsve": _nmsve(V, V_ref, _unique_edges(F, V.shape[0]), "bbox"),
    }
    if hausdorff_distance:
        ref_side = _Side(V_ref, F)
        h = _symmetric(_Side(V, F, like=ref_side), ref_side)
        out["hd_mean"] = h["hd_mean"]
        out["hd_max"] = h["hd_max"]
    return out
