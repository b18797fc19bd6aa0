"""Documented repairs for imperfect meshes (readers with ``repair=True``, :func:`clean_mesh`):
duplicate vertices are merged only on request (vertex order and count are kept otherwise),
degenerate faces dropped, duplicate faces keep their first occurrence, unreferenced vertices are
removed.
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
    """Merge vertices closer than ``tol``; returns ``(V_new, F_new, index_map)``, first
    occurrences keeping their relative order.

    Groups are the connected components of "distance <= ``tol``"; memory grows linearly with the
    vertex count, however many vertices coincide.
    """
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F", allow_empty=True)
    if V.shape[0] == 0:
        return V, F, np.zeros(0, dtype=np.int64)
    if tol > 0:
        labels = _near_components(V, float(tol))
    else:
        labels = np.unique(V, axis=0, return_inverse=True)[1].ravel()
    # representative = first occurrence of each label, in input order
    _, first = np.unique(labels, return_index=True)
    rep_sorted = np.sort(first)
    new_of_label = np.empty(labels.max() + 1, dtype=np.int64)
    new_of_label[labels[rep_sorted]] = np.arange(rep_sorted.size)
    index_map = new_of_label[labels]
    return V[rep_sorted], index_map[F], index_map


#: Cell pairs of :func:`_near_components` with more point pairs than this go through a k-d tree.
_PAIR_BLOCK = 256
#: Point pairs compared per vectorised step of :func:`_near_components`.
_PAIR_CHUNK = 1 << 20


def _near_components(U: np.ndarray, tol: float) -> np.ndarray:
    """Component label (u,) of each point of ``U`` under "distance <= ``tol``".

    Points in one cell of side ``tol / 2`` are within ``tol`` of each other; only cells whose
    keys lie within ``2 + sqrt(3)`` can hold other pairs, which are tested exactly. A ``tol``
    below ``2**-36`` of the extent merges exact duplicates only.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    lo = U.min(axis=0)
    side = tol / 2.0
    if float((U.max(axis=0) - lo).max()) > side * 2.0**36:
        return np.unique(U, axis=0, return_inverse=True)[1].ravel()
    key = np.floor((U - lo) / side).astype(np.int64)
    dims = key.max(axis=0) + 1
    if float(np.prod(dims.astype(np.float64))) < 2.0**62:  # one int64 per cell: a fast unique
        flat = (key[:, 0] * dims[1] + key[:, 1]) * dims[2] + key[:, 2]
        _, first, cell_of = np.unique(flat, return_index=True, return_inverse=True)
        cells = key[first].astype(np.float64)
    else:
        cells, cell_of = np.unique(key.astype(np.float64), axis=0, return_inverse=True)
    cell_of = cell_of.ravel()
    n_cells = cells.shape[0]
    cand = cKDTree(cells).query_pairs(2.0 + np.sqrt(3.0) + 1e-3, output_type="ndarray")
    if cand.size == 0:
        return cell_of
    order = np.argsort(cell_of, kind="stable")
    start = np.searchsorted(cell_of[order], np.arange(n_cells + 1))
    size = np.diff(start)
    a, b = cand[:, 0], cand[:, 1]
    prod = size[a] * size[b]
    small = prod <= _PAIR_BLOCK
    joined = [np.zeros(0, dtype=np.int64)] * 2
    sa, sb, sp = a[small], b[small], prod[small]
    ends = np.cumsum(sp)
    c0 = 0
    while c0 < sp.size:  # every point pair of the small cell pairs, in bounded chunks
        c1 = int(np.searchsorted(ends, ends[c0] - sp[c0] + _PAIR_CHUNK, side="right"))
        c1 = max(c1, c0 + 1)
        pa, pb, pp = sa[c0:c1], sb[c0:c1], sp[c0:c1]
        pair = np.repeat(np.arange(pp.size), pp)
        r = np.arange(pair.size) - np.repeat(np.cumsum(pp) - pp, pp)
        nb = size[pb][pair]
        i = order[start[pa][pair] + r // nb]
        j = order[start[pb][pair] + r % nb]
        hit = pair[((U[i] - U[j]) ** 2).sum(axis=1) <= tol * tol]
        joined = [np.concatenate([joined[0], pa[hit]]), np.concatenate([joined[1], pb[hit]])]
        c0 = c1
    G = coo_matrix((np.ones(joined[0].size), (joined[0], joined[1])), shape=(n_cells, n_cells))
    comp = connected_components(G, directed=False)[1]
    parent = np.arange(int(comp.max()) + 1)

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for x, y in cand[~small]:  # large cell pairs: one k-d tree query unless already joined
        rx, ry = find(int(comp[x])), find(int(comp[y]))
        if rx == ry:
            continue
        A = U[order[start[x] : start[x + 1]]]
        B = U[order[start[y] : start[y + 1]]]
        if A.shape[0] > B.shape[0]:
            A, B = B, A
        d = cKDTree(B).query(A, k=1, distance_upper_bound=2.0 * tol)[0]
        if (d <= tol).any():
            parent[rx] = ry
    while True:  # flatten the union-find forest
        nxt = parent[parent]
        if np.array_equal(nxt, parent):
            break
        parent = nxt
    return parent[comp][cell_of]


def remove_unreferenced(V, F) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drop vertices used by no face; returns ``(V_new, F_new, kept_indices)``."""
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F", allow_empty=True)
    keep = ~unreferenced_vertices(F, V.shape[0])
    new = np.cumsum(keep) - 1
    return V[keep], new[F], np.flatnonzero(keep)


@dataclass(frozen=True)
class RepairReport:
    """What :func:`clean_mesh` changed: counts of ``merged_vertices``, ``degenerate_faces``,
    ``duplicate_faces`` and ``unreferenced_vertices``.
    """

    merged_vertices: int
    degenerate_faces: int
    duplicate_faces: int
    unreferenced_vertices: int

    @property
    def changed(self) -> bool:
        """True when any count is non-zero."""
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
    """Apply the repair policies; returns the mesh (extras dropped when elements change) and a
    :class:`RepairReport`.
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


#: Default weld tolerance, relative to the bounding-box diagonal. Coordinates written in float32
#: (STL) or recomputed per triangle by CAD exporters differ by about 1e-7 of the part's size where
#: they mean the same point; the shortest edges of the shared CAD tessellations are >= 1e-5 of it.
WELD_TOL = 1e-6


@dataclass(frozen=True)
class Weld:
    """Result of :func:`weld`: welded ``vertices`` (k, 3) (each group's first vertex), re-indexed
    ``faces`` without collapsed ones, ``index_map`` (n,), ``face_kept`` (m,) and the absolute ``tol``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    index_map: np.ndarray
    face_kept: np.ndarray
    tol: float

    @property
    def n_merged(self) -> int:
        """Number of input vertices merged into an earlier one."""
        return int(self.index_map.size - self.vertices.shape[0])

    @property
    def n_dropped_faces(self) -> int:
        """Number of input faces that collapsed (two corners welded together)."""
        return int(self.face_kept.size - np.count_nonzero(self.face_kept))

    def expand(self, V_welded) -> np.ndarray:
        """Welded positions (k, 3) back in the input's order and count (n, 3)."""
        V_welded = np.asarray(V_welded)
        if V_welded.shape[0] != self.vertices.shape[0]:
            from .._errors import InvalidInputError

            raise InvalidInputError(
                f"`V_welded` must have {self.vertices.shape[0]} rows (the welded vertices); "
                f"got {V_welded.shape[0]}."
            )
        return V_welded[self.index_map]


def weld(V, F, *, tol: float = WELD_TOL) -> Weld:
    """Merge vertices that coincide within ``tol`` times the bounding-box diagonal.

    For triangle soups (STL), duplicated seam vertices and CAD corners differing in the last bits.
    Groups are the components of the "closer than ``tol * diag``" relation, represented by their
    first vertex; faces with two corners in a group are dropped. ``tol`` (>= 0, default
    :data:`WELD_TOL`) of 0 merges exact duplicates only. Returns a :class:`Weld`.
    """
    from .._errors import InvalidInputError

    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F", allow_empty=True)
    if not np.isfinite(tol) or tol < 0:
        raise InvalidInputError(f"`tol` must be a finite number >= 0; got {tol!r}.")
    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))) if V.shape[0] else 0.0
    abs_tol = tol * diag
    Vw, Fw, index_map = merge_duplicate_vertices(V, F, tol=abs_tol)
    kept = ~((Fw[:, 0] == Fw[:, 1]) | (Fw[:, 1] == Fw[:, 2]) | (Fw[:, 0] == Fw[:, 2]))
    return Weld(Vw, Fw[kept], index_map, kept, abs_tol)


def is_soup(F, n_vertices: int) -> bool:
    """True when no vertex is shared by two faces (and there are at least two faces)."""
    F = np.asarray(F, dtype=np.int64)
    if F.shape[0] < 2:
        return False
    counts = np.bincount(F.ravel(), minlength=n_vertices)
    return bool(counts.max() <= 1)
