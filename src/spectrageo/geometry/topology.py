"""Topology report of a triangle mesh (``spectrageo info``), vectorised over half-edges."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .._validation import as_faces, as_points
from .repair import degenerate_faces, unreferenced_vertices

__all__ = ["mesh_topology"]


def _n_duplicate_positions(V: np.ndarray) -> int:
    """Number of vertices whose coordinates equal those of an earlier vertex exactly."""
    if V.shape[0] < 2:
        return 0
    order = np.lexsort(V.T[::-1])
    S = V[order]
    return int(np.all(S[1:] == S[:-1], axis=1).sum())


def _n_duplicate_faces(F: np.ndarray, n: int) -> int:
    """Number of faces whose vertex set equals an earlier face's (two integer sort keys)."""
    if F.shape[0] < 2:
        return 0
    S = np.sort(F, axis=1)
    k01 = S[:, 0] * np.int64(n) + S[:, 1]  # exact while n**2 < 2**63
    o = np.lexsort((S[:, 2], k01))
    k01, k2 = k01[o], S[o, 2]
    return int(((k01[1:] == k01[:-1]) & (k2[1:] == k2[:-1])).sum())


def _components(n: int, i: np.ndarray, j: np.ndarray) -> tuple[int, np.ndarray]:
    G = sp.coo_matrix((np.ones(i.size, dtype=np.int8), (i, j)), shape=(n, n)).tocsr()
    return connected_components(G, directed=False)


def mesh_topology(V, F) -> dict:
    """Topological summary of the triangle mesh ``(V, F)`` as a dict of plain Python values.

    Counts ``n_vertices``, ``n_faces``, ``n_edges``, ``n_components`` (faces joined by shared
    vertices), ``n_boundary_loops``, ``n_boundary_edges``, ``n_nonmanifold_edges``,
    ``n_nonmanifold_vertices``, ``n_duplicate_vertices``, ``n_unreferenced_vertices``,
    ``n_degenerate_faces``, ``n_duplicate_faces``; derives ``euler_characteristic``, ``is_closed``,
    ``is_manifold`` and ``genus`` (None unless closed, manifold, connected, even ``chi``). ``V`` is
    used for duplicates and zero areas only. See docs/decisions.md#geometry-topology-definitions.
    """
    V = as_points(V, "V")
    n = V.shape[0]
    F = as_faces(F, n, "F", allow_empty=True)
    m = F.shape[0]

    n_unref = int(unreferenced_vertices(F, n).sum())
    n_deg = int(degenerate_faces(V, F).sum()) if m else 0
    n_dup_f = _n_duplicate_faces(F, n)
    n_dup_v = _n_duplicate_positions(V)

    # half-edges: side k of face f goes from corner 3f+k to corner 3f+(k+1)%3
    c0 = np.arange(3 * m, dtype=np.int64)
    c1 = (c0 // 3) * 3 + (c0 % 3 + 1) % 3
    flat = F.ravel()
    a, b = flat[c0], flat[c1]
    proper = a != b  # sides of degenerate faces with a repeated index are not edges
    c0, c1, a, b = c0[proper], c1[proper], a[proper], b[proper]
    lo_is_a = a < b
    key = np.where(lo_is_a, a, b) * np.int64(max(n, 1)) + np.where(lo_is_a, b, a)
    order = np.argsort(key)
    ks = key[order]
    new_group = np.r_[True, ks[1:] != ks[:-1]] if ks.size else np.zeros(0, dtype=bool)
    gid_sorted = np.cumsum(new_group) - 1
    n_edges = int(new_group.sum())
    counts = np.bincount(gid_sorted, minlength=n_edges)
    gid = np.empty_like(gid_sorted)
    gid[order] = gid_sorted
    use = counts[gid]  # faces on the edge of each half-edge
    n_boundary_edges = int((counts == 1).sum())
    n_nonmanifold_edges = int((counts > 2).sum())

    # fans: (vertex, face) incidences (corners) joined through the faces' shared edges
    first = order[new_group][gid]  # index of the group's first half-edge, per half-edge
    lo_c = np.where(lo_is_a, c0, c1)
    hi_c = np.where(lo_is_a, c1, c0)
    # a vertex repeated in a face is one incidence: join its corners
    f = np.arange(m)
    same = [(F[:, p] == F[:, q], 3 * f + p, 3 * f + q) for p, q in ((0, 1), (1, 2), (0, 2))]
    ii = np.concatenate([lo_c, hi_c] + [s[1][s[0]] for s in same])
    jj = np.concatenate([lo_c[first], hi_c[first]] + [s[2][s[0]] for s in same])
    keep = ii != jj  # an edge's first half-edge would join its corners to themselves
    n_fans_total, fan = _components(3 * m, ii[keep], jj[keep])
    fan_vertex = np.empty(n_fans_total, dtype=np.int64)
    fan_vertex[fan] = flat
    fans_per_vertex = np.bincount(fan_vertex, minlength=n)
    n_nonmanifold_vertices = int((fans_per_vertex > 1).sum())

    # boundary loops: components of the boundary edges between fans
    bnd = use == 1
    if bnd.any():
        _, loop = _components(n_fans_total, fan[c0[bnd]], fan[c1[bnd]])
        n_loops = int(np.unique(loop[fan[c0[bnd]]]).size)
    else:
        n_loops = 0

    # components of faces through shared vertices: vertex graph of the face sides
    if m:
        _, vlab = _components(n, np.r_[F[:, 0], F[:, 1]], np.r_[F[:, 1], F[:, 2]])
        used = np.zeros(n, dtype=bool)
        used[flat] = True
        n_components = int(np.unique(vlab[used]).size)
    else:
        n_components = 0

    chi = (n - n_unref) - n_edges + m
    is_closed = m > 0 and n_boundary_edges == 0
    is_manifold = n_nonmanifold_edges == 0 and n_nonmanifold_vertices == 0
    genus = None
    if is_closed and is_manifold and n_components == 1 and chi % 2 == 0:
        genus = (2 - chi) // 2
    return {
        "n_vertices": int(n),
        "n_faces": int(m),
        "n_edges": n_edges,
        "n_components": n_components,
        "n_boundary_loops": n_loops,
        "n_boundary_edges": n_boundary_edges,
        "n_nonmanifold_edges": n_nonmanifold_edges,
        "n_nonmanifold_vertices": n_nonmanifold_vertices,
        "n_duplicate_vertices": n_dup_v,
        "n_unreferenced_vertices": n_unref,
        "n_degenerate_faces": n_deg,
        "n_duplicate_faces": n_dup_f,
        "euler_characteristic": int(chi),
        "is_closed": bool(is_closed),
        "is_manifold": bool(is_manifold),
        "genus": None if genus is None else int(genus),
    }
