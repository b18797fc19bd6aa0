"""Topology report of a triangle mesh (used by ``spectrageo info``).

:func:`mesh_topology` counts components, boundary loops, non-manifold edges and vertices, duplicate,
unreferenced and degenerate elements, and derives the Euler characteristic and the genus. Everything
is vectorised over faces and half-edges with numpy and :mod:`scipy.sparse.csgraph`; no Python loop
runs over vertices, faces or edges.

Definitions (all on the faces as given: degenerate and duplicate faces are counted, not dropped):

* **edges** are the unordered vertex pairs of the face sides; a side whose two indices are equal
  (a degenerate face such as ``(0, 0, 1)``) is not an edge, as in :func:`~.primitives.edges`.
  An edge used by exactly one face is a *boundary edge*, by more than two a *non-manifold edge*.
* a **fan** of a vertex ``v`` is a maximal set of faces around ``v`` connected through edges incident
  to ``v`` (the components of ``v``'s link). Fans are the connected components of the graph whose
  nodes are the (vertex, face) incidences and whose arcs join ``(v, f)`` and ``(v, g)`` when the faces
  ``f`` and ``g`` share an edge ``{v, w}``. A vertex with more than one fan is a *non-manifold
  vertex* (a "bowtie" or pinch vertex). A vertex lying on a non-manifold edge has a single fan there
  and is reported through ``n_nonmanifold_edges`` only.
* a **connected component** is a set of faces connected by sharing a vertex (not only an edge), so
  two tetrahedra glued at one vertex form one component. Vertices used by no face are not counted as
  components; they are reported as ``n_unreferenced_vertices``.
* a **boundary loop** is a connected component of the boundary edges after every non-manifold vertex
  has been split into its fans (each boundary edge joins the fans of its two endpoints in its face).
  This is what a walk along the boundary counts when, at a vertex it passes more than once, it
  leaves through the fan it arrived by. Thus a bowtie of two triangles sharing a vertex has two
  loops (one per triangle) although its boundary edges form one connected figure-eight, while a strip
  whose two ends touch at one vertex has one loop (its border) although that boundary also passes
  twice through the pinch vertex. The count depends neither on the order of the faces nor on their
  orientation. :func:`~.primitives.boundary_loops`, which leaves a pinch vertex by its first unused
  boundary edge, returns one or two loops in both examples depending on the face order, so it is
  not used here. Boundary loops meeting at a non-manifold edge (three triangles on one edge) form
  one connected component and are counted once.
"""

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
    """Number of faces whose vertex set equals an earlier face's.

    Same count as ``repair.duplicate_faces(F).sum()``, which sorts rows with ``np.unique(axis=0)``
    (0.85 s on 871k faces); two integer sort keys take about a tenth of that.
    """
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
    """Topological summary of the triangle mesh ``(V, F)`` as plain Python values.

    See the module docstring for the exact definitions of components, fans and boundary loops.

    Parameters
    ----------
    V : (n, 3) array_like of float
        Vertex positions (used for duplicate vertices and zero-area faces only).
    F : (m, 3) array_like of int
        Triangles, indices into ``V``; int32 is accepted and upcast.

    Returns
    -------
    dict
        ``n_vertices``, ``n_faces``, ``n_edges`` (unique edges), and

        * ``n_components``: connected components of the faces via shared vertices (isolated vertices
          are not components);
        * ``n_boundary_loops``: closed boundary loops (a figure-eight counts as two);
        * ``n_boundary_edges``: edges used by exactly one face;
        * ``n_nonmanifold_edges``: edges used by more than two faces;
        * ``n_nonmanifold_vertices``: vertices whose incident faces form more than one fan;
        * ``n_duplicate_vertices``: vertices whose position equals an earlier vertex's exactly;
        * ``n_unreferenced_vertices``: vertices used by no face;
        * ``n_degenerate_faces``: faces with a repeated index or zero area;
        * ``n_duplicate_faces``: faces whose vertex set already appeared in an earlier face;
        * ``euler_characteristic``: ``V - E + F`` over the referenced vertices, the unique edges and
          all faces;
        * ``is_closed``: at least one face and no boundary edge;
        * ``is_manifold``: no non-manifold edge and no non-manifold vertex;
        * ``genus``: ``(2 - chi) / 2`` when the mesh is closed, manifold, has one component and an
          even ``chi``, else ``None``. Orientability is not checked: a closed non-orientable surface
          of even ``chi`` (a Klein bottle) would be reported with the genus of the orientable surface
          of that ``chi``.
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
