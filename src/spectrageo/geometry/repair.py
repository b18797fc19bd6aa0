"""Documented repairs for imperfect meshes.

Policies (used by readers when ``repair=True`` and by :func:`clean_mesh`):

* duplicate vertices (identical coordinates) are merged only on request — vertex order and count
  are otherwise preserved exactly, because ground-truth pairs and animations depend on them;
* degenerate faces (repeated index or zero area) are dropped;
* duplicate faces (same vertex set) keep their first occurrence;
* unreferenced vertices are removed and faces re-indexed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validation import as_faces, as_points
from .data import Mesh


def degenerate_faces(V, F, *, area_tol: float = 0.0) -> np.ndarray:
    """Boolean (m,) mask of faces with a repeated index or area ``<= area_tol``."""
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F", allow_empty=True)
    rep = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
    cr = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    return rep | (0.5 * np.linalg.norm(cr, axis=1) <= area_tol)


def duplicate_faces(F) -> np.ndarray:
    """Boolean (m,) mask of faces whose vertex set already appeared earlier."""
    F = np.asarray(F, dtype=np.int64)
    if F.size == 0:
        return np.zeros(0, dtype=bool)
    key = np.sort(F, axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    mask = np.ones(len(F), dtype=bool)
    mask[first] = False
    return mask


def unreferenced_vertices(F, n_vertices: int) -> np.ndarray:
    """Boolean (n,) mask of vertices used by no face."""
    used = np.zeros(n_vertices, dtype=bool)
    used[np.asarray(F, dtype=np.int64).ravel()] = True
    return ~used


def merge_duplicate_vertices(
    V, F, *, tol: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Merge vertices closer than ``tol`` (exact duplicates by default).

    Returns ``(V_new, F_new, index_map)`` where ``index_map[i]`` is the new index of old vertex ``i``;
    the first occurrence of a group keeps its position and relative order.
    """
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F", allow_empty=True)
    if tol > 0:
        from scipy.sparse.csgraph import connected_components
        from scipy.spatial import cKDTree

        pairs = cKDTree(V).query_pairs(tol, output_type="ndarray")
        import scipy.sparse as sp

        G = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(V), len(V)))
        _, labels = connected_components(G, directed=False)
    else:
        _, labels = np.unique(V, axis=0, return_inverse=True)
        labels = labels.ravel()
    # representative = first occurrence of each label, in input order
    _, first = np.unique(labels, return_index=True)
    rep_sorted = np.sort(first)
    new_of_label = np.empty(labels.max() + 1, dtype=np.int64)
    new_of_label[labels[rep_sorted]] = np.arange(rep_sorted.size)
    index_map = new_of_label[labels]
    return V[rep_sorted], index_map[F], index_map


def remove_unreferenced(V, F) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drop vertices used by no face; returns ``(V_new, F_new, kept_indices)``."""
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F", allow_empty=True)
    keep = ~unreferenced_vertices(F, V.shape[0])
    new = np.cumsum(keep) - 1
    return V[keep], new[F], np.flatnonzero(keep)


@dataclass(frozen=True)
class RepairReport:
    merged_vertices: int
    degenerate_faces: int
    duplicate_faces: int
    unreferenced_vertices: int

    @property
    def changed(self) -> bool:
        return any(
            (
                self.merged_vertices,
                self.degenerate_faces,
                self.duplicate_faces,
                self.unreferenced_vertices,
            )
        )


def clean_mesh(
    mesh: Mesh,
    *,
    merge_vertices: bool = False,
    merge_tol: float = 0.0,
    drop_degenerate: bool = True,
    drop_duplicate_faces: bool = True,
    drop_unreferenced: bool = True,
) -> tuple[Mesh, RepairReport]:
    """Apply the repair policies above; returns the repaired mesh and a report of what changed.

    Per-vertex/per-face extras are dropped when the vertex or face set changes.
    """
    V, F = mesh.vertices, mesh.faces
    merged = deg = dup = unref = 0
    if merge_vertices:
        V2, F, _ = merge_duplicate_vertices(V, F, tol=merge_tol)
        merged = len(V) - len(V2)
        V = V2
    if drop_degenerate:
        bad = degenerate_faces(V, F)
        deg = int(bad.sum())
        F = F[~bad]
    if drop_duplicate_faces:
        bad = duplicate_faces(F)
        dup = int(bad.sum())
        F = F[~bad]
    if drop_unreferenced:
        V2, F, _ = remove_unreferenced(V, F)
        unref = len(V) - len(V2)
        V = V2
    report = RepairReport(merged, deg, dup, unref)
    if not report.changed:
        return mesh, report
    return Mesh(V, F), report
