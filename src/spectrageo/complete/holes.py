"""Hole filling with unknown connectivity (thesis Section 5.3.1, last scenario)."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import Delaunay

from .._errors import InvalidInputError
from .._progress import activity, progress
from .._validation import as_faces, as_points, check_choice, check_positive
from ..geometry import boundary_edges, boundary_loops, weld
from ..geometry.primitives import _normalize_rows
from .static import INPAINT_METHODS, inpaint

__all__ = ["DP_MAX_LOOP", "FAIR_RINGS", "MAX_IMPLANTED", "FilledMesh", "OpenLoop", "fill_holes"]

#: Loops with more edges are cut into pieces by chords before they are patched: the planar
#: patch's tests cost O(L^2) memory and Liepa's dynamic programming O(L^3) time (about 2.6 s at
#: 300 edges, minutes at 2000). The open border of a scan is such a loop; it is filled at the
#: density of its edges, and ``max_hole`` leaves it open.
DP_MAX_LOOP = 300

#: Most points :func:`fill_holes` implants in one call (estimated from the holes' areas before
#: any is built): about 20 GB of memory at the measured 10 kB per implanted point, so a
#: ``density`` typed too large is refused with a clear error instead of exhausting memory.
MAX_IMPLANTED = 2_000_000


def _lattice_count(P: np.ndarray, h: float) -> float:
    """Hexagonal lattice points of spacing ``h`` inside the projected loop ``P``."""
    if not h > 0:
        return 0.0
    Q = P - P.mean(axis=0)
    _, _, vt = np.linalg.svd(Q, full_matrices=False)
    x, y = Q @ vt[0], Q @ vt[1]
    area = 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
    return area / (h * h * np.sqrt(3.0) / 2.0)


# ------------------------------------------------------------------ planar patch (scipy Delaunay)
def _segments_cross(Q: np.ndarray) -> bool:
    """Whether two non-adjacent edges of the closed polygon ``Q`` (L, 2) cross or touch."""
    L = Q.shape[0]
    a, b = Q, np.roll(Q, -1, axis=0)
    i, j = np.triu_indices(L, 2)
    keep = ~((i == 0) & (j == L - 1))
    i, j = i[keep], j[keep]
    span = float(np.max(np.ptp(Q, axis=0))) if L else 0.0
    eps = 1e-12 * span * span

    def orient(p, q, r):
        return (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])

    def on_segment(p, q, r):  # r (collinear with p q) inside the bounding box of p q
        lo, hi = np.minimum(p, q), np.maximum(p, q)
        return np.all((r >= lo - 1e-12 * span) & (r <= hi + 1e-12 * span), axis=1)

    d1 = orient(a[i], b[i], a[j])
    d2 = orient(a[i], b[i], b[j])
    d3 = orient(a[j], b[j], a[i])
    d4 = orient(a[j], b[j], b[i])
    proper = (d1 * d2 < 0) & (d3 * d4 < 0)
    touch = (
        ((np.abs(d1) <= eps) & on_segment(a[i], b[i], a[j]))
        | ((np.abs(d2) <= eps) & on_segment(a[i], b[i], b[j]))
        | ((np.abs(d3) <= eps) & on_segment(a[j], b[j], a[i]))
        | ((np.abs(d4) <= eps) & on_segment(a[j], b[j], b[i]))
    )
    return bool(np.any(proper | touch))


def _inside(Q: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test of ``pts`` (p, 2) against the closed polygon ``Q``."""
    a, b = Q[None, :, :], np.roll(Q, -1, axis=0)[None, :, :]
    x, y = pts[:, None, 0], pts[:, None, 1]
    cond = (a[..., 1] > y) != (b[..., 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xs = a[..., 0] + (y - a[..., 1]) * (b[..., 0] - a[..., 0]) / (b[..., 1] - a[..., 1])
    return (np.count_nonzero(cond & (x < xs), axis=1) % 2) == 1


def _seg_dist(Q: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Distance of ``pts`` to the closed polygon ``Q``."""
    a, b = Q, np.roll(Q, -1, axis=0)
    ab = b - a
    t = np.clip(
        ((pts[:, None, :] - a[None]) * ab[None]).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-300),
        0.0,
        1.0,
    )
    proj = a[None] + t[..., None] * ab[None]
    return np.sqrt(((pts[:, None, :] - proj) ** 2).sum(-1)).min(axis=1)


def _planar_patch(P: np.ndarray, h: float):
    """``(tri, new_points)`` by Delaunay of the projected loop and lattice, or None."""
    L = P.shape[0]
    c = P.mean(axis=0)
    _, _, Vt = np.linalg.svd(P - c, full_matrices=False)
    Q = (P - c) @ Vt[:2].T
    if _segments_cross(Q):
        return None
    lo, hi = Q.min(axis=0), Q.max(axis=0)
    dy = h * np.sqrt(3.0) / 2.0
    ys = np.arange(lo[1] + dy / 2, hi[1], dy)
    pts = []
    for r, y in enumerate(ys):  # hexagonal lattice, rows offset by h/2
        xs = np.arange(lo[0] + (h / 2 if r % 2 else 0.0), hi[0], h)
        pts.append(np.column_stack([xs, np.full(xs.size, y)]))
    G = np.concatenate(pts) if pts else np.zeros((0, 2))
    if G.shape[0]:
        G = G[_inside(Q, G)]
    if G.shape[0]:
        G = G[_seg_dist(Q, G) > 0.6 * h]
    allp = np.concatenate([Q, G])
    # four far corners keep the loop off the convex hull, where Qhull drops collinear points
    # (a straight side of a CAD hole, a splitting chord); their triangles are removed below
    mid, ext = 0.5 * (lo + hi), 10.0 * float(np.max(hi - lo)) + h
    box = mid + ext * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    try:
        tri = Delaunay(np.concatenate([allp, box])).simplices
    except Exception:  # noqa: BLE001 - qhull errors (degenerate input) mean "use the fallback"
        return None
    tri = tri[(tri < allp.shape[0]).all(axis=1)]
    d1, d2 = allp[tri[:, 1]] - allp[tri[:, 0]], allp[tri[:, 2]] - allp[tri[:, 0]]
    flat = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) <= 1e-9 * h * h
    tri = tri[~flat]  # collinear boundary points (a splitting chord): no zero-area triangle
    cen = allp[tri].mean(axis=1)
    tri = tri[_inside(Q, cen)]
    # every loop edge must be an edge of the patch, used once; inner edges twice
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    key, cnt = np.unique(e[:, 0] * allp.shape[0] + e[:, 1], return_counts=True)
    once = set(key[cnt == 1].tolist())
    li = np.arange(L)
    loop = np.sort(np.column_stack([li, (li + 1) % L]), axis=1)
    want = set((loop[:, 0] * allp.shape[0] + loop[:, 1]).tolist())
    if once != want or np.any(cnt > 2):
        return None
    new3 = c + G @ Vt[:2]
    return tri, new3


# ------------------------------------------- fallback: Liepa's minimum-weight patch + refinement
def _dp_patch(
    P: np.ndarray,
    h: float,
    forbid: np.ndarray | None = None,
    max_splits: int = 6,
    border_normals: np.ndarray | None = None,
):
    """Liepa's minimum-weight triangulation of the loop, then centroid splits; None if ``forbid``
    rules out every triangulation.
    """
    L = P.shape[0]
    nb = np.full((L, 3), np.nan) if border_normals is None else border_normals
    ang_of = np.full((L, L), np.inf)
    area_of = np.full((L, L), np.inf)
    nrm_of = np.full((L, L, 3), np.nan)  # normal of the triangle chosen on chord (i, j)
    O = np.full((L, L), -1, dtype=np.int64)
    i1 = np.arange(L - 1)
    ang_of[i1, i1 + 1] = 0.0
    area_of[i1, i1 + 1] = 0.0

    def angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        c = np.sum(a * b, axis=-1)
        return np.arccos(np.clip(np.where(np.isnan(c), 1.0, c), -1.0, 1.0))

    scale2 = float(np.max(np.sum((P - P.mean(axis=0)) ** 2, axis=1)))
    for gap in range(2, L):
        for i in range(0, L - gap):
            j = i + gap
            m = np.arange(i + 1, j)
            cr = np.cross(P[j] - P[i], P[m] - P[i])
            nt = _normalize_rows(cr)
            n_im = np.where((m == i + 1)[:, None], nb[i][None], nrm_of[i, m])
            n_mj = np.where((m == j - 1)[:, None], nb[m], nrm_of[m, j])
            ang = np.maximum(angle(nt, n_im), angle(nt, n_mj))
            if i == 0 and j == L - 1:  # the last loop edge closes the patch
                ang = np.maximum(ang, angle(nt, nb[L - 1][None]))
            ang = np.maximum(ang, np.maximum(ang_of[i, m], ang_of[m, j]))
            area = 0.5 * np.linalg.norm(cr, axis=1)
            tot = area + area_of[i, m] + area_of[m, j]
            # no zero-area triangle (collinear loop points, e.g. along a splitting chord)
            ang = np.where(area <= 1e-12 * scale2, np.inf, ang)
            if forbid is not None:
                ang = np.where(forbid[i, m] | forbid[m, j], np.inf, ang)
            best = ang.min()
            if not np.isfinite(best):
                continue
            b = int(np.argmin(np.where(ang <= best + 1e-9, tot, np.inf)))
            ang_of[i, j], area_of[i, j], O[i, j] = ang[b], tot[b], m[b]
            nrm_of[i, j] = nt[b]
    if not np.isfinite(ang_of[0, L - 1]):
        return None
    tris = []
    stack = [(0, L - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        m = int(O[i, j])
        tris.append((i, m, j))
        stack.append((i, m))
        stack.append((m, j))
    tri = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    return _refine(P, tri, h, max_splits)


def _refine(P: np.ndarray, tri: np.ndarray, h: float, max_splits: int):
    """Split triangles above twice the equilateral of side ``h`` 1-to-3, ``max_splits`` rounds."""
    L = P.shape[0]
    pts = [p for p in P]
    target = np.sqrt(3.0) / 4.0 * h * h
    for _ in range(max_splits):
        X = np.asarray(pts)
        area = 0.5 * np.linalg.norm(
            np.cross(X[tri[:, 1]] - X[tri[:, 0]], X[tri[:, 2]] - X[tri[:, 0]]), axis=1
        )
        big = area > 2.0 * target
        if not big.any():
            break
        cen = X[tri[big]].mean(axis=1)
        ids = np.arange(len(pts), len(pts) + cen.shape[0])
        pts.extend(cen)
        a, b, c = tri[big, 0], tri[big, 1], tri[big, 2]
        tri = np.concatenate(
            [tri[~big], np.column_stack([a, b, ids]), np.column_stack([b, c, ids]),
             np.column_stack([c, a, ids])]
        )  # fmt: skip
    new3 = np.asarray(pts[L:]).reshape(-1, 3)
    return tri, new3


def _directed_faces(F: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (3m, 3) of every face sorted by their leading directed edge, and the keys."""
    T = np.concatenate([F[:, [0, 1, 2]], F[:, [1, 2, 0]], F[:, [2, 0, 1]]])
    key = T[:, 0] * n + T[:, 1]
    order = np.argsort(key, kind="stable")
    return T[order], key[order]


def _border_normals(V: np.ndarray, faces: tuple, loop: np.ndarray, n: int) -> np.ndarray:
    """Unit normals of the mesh faces on the loop edges, oriented for :func:`_dp_patch`."""
    T, ks = faces
    a, b = loop, np.roll(loop, -1)
    out = np.full((loop.size, 3), np.nan)
    for q, p, sign in ((a, b, 1.0), (b, a, -1.0)):  # the face runs a -> b (boundary) or b -> a
        want = q * n + p
        pos = np.minimum(np.searchsorted(ks, want), ks.size - 1)
        hit = (ks[pos] == want) & np.isnan(out[:, 0])
        if hit.any():
            t = T[pos[hit]]
            nf = np.cross(V[t[:, 1]] - V[t[:, 0]], V[t[:, 2]] - V[t[:, 0]])
            out[hit] = sign * _normalize_rows(nf)
    return out


def _simple_loops(loop: np.ndarray) -> list[np.ndarray]:
    """Split a boundary loop that passes a vertex twice into simple cycles."""
    out, stack, pos = [], [], {}
    for v in loop.tolist():
        if v in pos:
            p = pos[v]
            cyc = stack[p:]
            for u in cyc[1:]:
                del pos[u]
            del stack[p + 1 :]
            if len(cyc) >= 3:
                out.append(np.asarray(cyc, dtype=np.int64))
        else:
            pos[v] = len(stack)
            stack.append(v)
    if len(stack) >= 3:
        out.append(np.asarray(stack, dtype=np.int64))
    return out


def _in_sorted(q: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """``np.isin(q, keys)`` for sorted ``keys`` by binary search."""
    if keys.size == 0:
        return np.zeros(np.shape(q), dtype=bool)
    pos = np.minimum(np.searchsorted(keys, q), keys.size - 1)
    return keys[pos] == q


def _chords_ok(tri: np.ndarray, loop: np.ndarray, ctx: _Context) -> bool:
    """No patch chord between loop vertices may already be a mesh edge."""
    L = loop.size
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    e = e[(e < L).all(axis=1)]
    d = np.abs(e[:, 0] - e[:, 1])
    e = e[(d != 1) & (d != L - 1)]
    if e.size == 0:
        return True
    g = np.sort(loop[e], axis=1)
    return not ctx.has_edge(g[:, 0] * ctx.n + g[:, 1]).any()


def _fan_patch(P: np.ndarray):
    """Last resort: a fan around the loop's centroid."""
    L = P.shape[0]
    i = np.arange(L)
    return np.column_stack([i, (i + 1) % L, np.full(L, L)]), P.mean(axis=0)[None]


class _Context:
    """Mesh data a loop patch needs (faces' directed rotations built on first use)."""

    def __init__(self, V: np.ndarray, F: np.ndarray, n: int, edge_keys: np.ndarray):
        self.V, self.F, self.n, self.edge_keys = V, F, n, edge_keys
        self.added_keys = np.zeros(0, dtype=np.int64)  # edges of the patches accepted so far
        self._faces = None

    def has_edge(self, keys: np.ndarray) -> np.ndarray:
        """Whether the edges ``keys`` (``a * n + b``, ``a < b``) are in the mesh or a patch."""
        return _in_sorted(keys, self.edge_keys) | _in_sorted(keys, self.added_keys)

    def add_edges(self, faces: np.ndarray) -> None:
        """Record the edges of an accepted patch ``faces`` between mesh vertices."""
        E = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        E = E[(E < self.n).all(axis=1)]
        keys = E[:, 0] * self.n + E[:, 1]
        keys = keys[~_in_sorted(keys, self.edge_keys)]  # chords
        if keys.size:
            self.added_keys = np.union1d(self.added_keys, keys)

    @property
    def faces(self) -> tuple:
        if self._faces is None:
            self._faces = _directed_faces(self.F, self.n)
        return self._faces


def _orient_local(tri: np.ndarray) -> np.ndarray:
    """Orient a local patch to traverse the loop edge ``0 -> 1`` backwards."""
    for f in tri:
        for s in range(3):
            if f[s] == 0 and f[(s + 1) % 3] == 1:
                return tri[:, ::-1].copy()
            if f[s] == 1 and f[(s + 1) % 3] == 0:
                return tri
    return tri  # pragma: no cover - every loop edge is in the patch


def _loop_patch(loop: np.ndarray, P: np.ndarray, h: float, ctx: _Context):
    """Oriented patch ``(tri, new points)`` of one loop."""
    L = P.shape[0]
    n = ctx.n
    if L == 3:
        return _orient_local(np.array([[0, 1, 2]])), np.zeros((0, 3))
    if L > DP_MAX_LOOP:
        return _split_patch(loop, P, h, ctx)
    got = _planar_patch(P, h) if h > 0 else None
    if got is not None and not _chords_ok(got[0], loop, ctx):
        got = None
    if got is None:
        g = np.sort(np.stack(np.meshgrid(loop, loop, indexing="ij"), axis=-1), axis=-1)
        forbid = ctx.has_edge(g[..., 0] * n + g[..., 1]) & (g[..., 0] >= 0)
        idx = np.arange(L)
        forbid[idx, (idx + 1) % L] = forbid[(idx + 1) % L, idx] = False
        nb = _border_normals(ctx.V, ctx.faces, loop, n)
        got = _dp_patch(P, h, forbid, border_normals=nb)
    tri, new3 = got if got is not None else _fan_patch(P)
    return _orient_local(tri), new3


def _split_patch(loop: np.ndarray, P: np.ndarray, h: float, ctx: _Context):
    """Patch of a loop of more than :data:`DP_MAX_LOOP` edges, cut by its shortest chord."""
    L = P.shape[0]
    half = L // 2
    i = np.arange(L)
    d = np.linalg.norm(P - P[(i + half) % L], axis=1)
    a = int(np.argmin(d))
    b = (a + half) % L
    m = min(max(int(round(d[a] / h)) - 1, 0), L // 4) if h > 0 else 0
    t = np.arange(1, m + 1) / (m + 1)
    chord = P[a] + t[:, None] * (P[b] - P[a])  # from a towards b
    cid = L + np.arange(m)
    halves = (
        np.concatenate([(a + np.arange(half + 1)) % L, cid[::-1]]),  # a..b, chord back to a
        np.concatenate([(b + np.arange(L - half + 1)) % L, cid]),  # b..a, chord on to b
    )
    P_all = np.concatenate([P, chord])
    ids_all = np.concatenate([loop, np.full(m, -1, dtype=np.int64)])
    tris, news, count = [], [chord], L + m
    for lo in halves:
        tri_s, new_s = _loop_patch(ids_all[lo], P_all[lo], h, ctx)
        mapping = np.concatenate([lo, count + np.arange(new_s.shape[0])])
        tris.append(mapping[tri_s])
        news.append(new_s)
        count += new_s.shape[0]
    return np.concatenate(tris), np.concatenate(news)


class OpenLoop(NamedTuple):
    """A boundary loop :func:`fill_holes` left open: its input vertex indices and why."""

    vertices: np.ndarray
    reason: str


#: Reasons a loop is left open (``OpenLoop.reason``).
OPEN_MAX_HOLE = "longer than max_hole (--max-hole)"
OPEN_NOT_CLOSED = (
    "not one closed border (borders meet at a vertex where their faces are wound inconsistently)"
)
OPEN_NON_ORIENTABLE = "on a non-orientable surface (such as a Moebius strip)"
OPEN_UNCOVERED = "whose fill would not cover every edge of it"
OPEN_DUPLICATE = "whose fill would duplicate a face"
OPEN_NON_MANIFOLD = "whose fill would give an edge more than two faces"


class FilledMesh(tuple):
    """``(V, F)`` returned by :func:`fill_holes`, with ``n_loops`` (boundary loops found, seams
    excluded) and ``open_loops`` (an :class:`OpenLoop` per loop left open)."""

    def __new__(cls, V: np.ndarray, F: np.ndarray, n_loops: int, open_loops: list):
        self = super().__new__(cls, (V, F))
        self.n_loops = int(n_loops)
        self.open_loops = tuple(open_loops)
        return self

    def __getnewargs__(self):
        return (self[0], self[1], self.n_loops, self.open_loops)

    @property
    def vertices(self) -> np.ndarray:
        return self[0]

    @property
    def faces(self) -> np.ndarray:
        return self[1]

    @property
    def n_filled(self) -> int:
        return self.n_loops - len(self.open_loops)


def _seam_map(V: np.ndarray, F: np.ndarray, n: int) -> np.ndarray:
    """Each vertex's representative: the first coincident border copy for border vertices."""
    to = np.arange(n)
    onb = np.zeros(n, dtype=bool)
    onb[boundary_edges(F, n).ravel()] = True
    if onb.any():
        g = weld(V, F).index_map
        rep = np.full(int(g.max()) + 1, -1, dtype=np.int64)
        order = np.flatnonzero(onb)[::-1]
        rep[g[order]] = order
        to = np.where(onb, rep[g], to)
    return to


class _Checker:
    """Welded-mesh edge counts and faces around a loop, to refuse fills that would duplicate a
    face or give an edge more than two faces (the fills accepted so far included)."""

    def __init__(self, Fw: np.ndarray, n: int):
        self.n, self.Fw = n, Fw
        E = np.sort(np.concatenate([Fw[:, [0, 1]], Fw[:, [1, 2]], Fw[:, [2, 0]]]), axis=1)
        self.ekey, self.ecnt = np.unique(E[:, 0] * n + E[:, 1], return_counts=True)
        m = Fw.shape[0]
        self.inc = sp.csr_matrix(
            (np.ones(3 * m, dtype=bool), (Fw.ravel(), np.repeat(np.arange(m), 3))), shape=(n, m)
        )
        self.added_e: dict[int, int] = {}
        self.added_f: dict[int, list] = {}

    def count(self, keys: np.ndarray) -> np.ndarray:
        """Faces on the edges ``keys`` (``a * n + b``, ``a < b``)."""
        pos = np.minimum(np.searchsorted(self.ekey, keys), self.ekey.size - 1)
        c = np.where(self.ekey[pos] == keys, self.ecnt[pos], 0)
        return c + np.array([self.added_e.get(k, 0) for k in keys.tolist()], dtype=np.int64)

    def loop_closed(self, loop: np.ndarray) -> bool:
        a, b = loop, np.roll(loop, -1)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        return bool(np.all(self.count(lo * self.n + hi) == 1))

    def faces_on(self, loop: np.ndarray) -> np.ndarray:
        """Faces of the mesh with a corner on ``loop``."""
        return np.unique(self.inc[loop].indices)

    def problem(self, loop: np.ndarray, faces: np.ndarray) -> str | None:
        n = self.n
        Fs = np.sort(faces, axis=1)
        if np.unique(Fs, axis=0).shape[0] < Fs.shape[0]:
            return OPEN_DUPLICATE
        old = Fs[(Fs < n).all(axis=1)]
        if old.shape[0]:
            near = [self.Fw[self.faces_on(loop)]]
            near += [np.asarray(self.added_f[v]) for v in loop.tolist() if v in self.added_f]
            have = {tuple(f) for f in np.sort(np.concatenate(near), axis=1).tolist()}
            if any(tuple(f) in have for f in old.tolist()):
                return OPEN_DUPLICATE
        E = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        N = int(faces.max()) + 1
        key, cnt = np.unique(E[:, 0] * N + E[:, 1], return_counts=True)
        a, b = key // N, key % N
        old_e = b < n  # both ends are mesh vertices
        total = cnt.copy()
        total[old_e] += self.count(a[old_e] * n + b[old_e])
        if np.any(total > 2):
            return OPEN_NON_MANIFOLD
        lo, hi = np.minimum(loop, np.roll(loop, -1)), np.maximum(loop, np.roll(loop, -1))
        if not np.all(self.count(lo * n + hi) + _in_sorted(lo * N + hi, key) == 2):
            return OPEN_UNCOVERED
        return None

    def add(self, faces: np.ndarray) -> None:
        n = self.n
        for f in faces[(faces < n).all(axis=1)].tolist():  # faces a later fill could repeat
            for v in f:
                self.added_f.setdefault(v, []).append(f)
        E = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        for k in (E[(E < n).all(axis=1)] @ np.array([n, 1])).tolist():
            self.added_e[k] = self.added_e.get(k, 0) + 1


def _half_edges(F: np.ndarray) -> np.ndarray:
    """(3m, 2) directed edges of the faces, all first edges, then all second, then all third."""
    return np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])


def _loop_copies(loops: list, F: np.ndarray, Fw: np.ndarray, n: int) -> list:
    """For each welded loop, the input vertex of each loop vertex in the face on its next edge."""
    H = _half_edges(Fw)
    Ho = _half_edges(F)
    key = H[:, 0] * n + H[:, 1]
    order = np.argsort(key, kind="stable")
    key, Ho = key[order], Ho[order]
    out = []
    for loop in loops:
        nxt = np.roll(loop, -1)
        cp = loop.copy()
        for q, end in ((loop * n + nxt, 0), (nxt * n + loop, 1)):  # the face runs u->v or v->u
            pos = np.minimum(np.searchsorted(key, q), key.size - 1)
            hit = (key[pos] == q) & (cp == loop)
            cp[hit] = Ho[pos[hit], end]
        out.append(cp)
    return out


def _non_orientable(Fw: np.ndarray, n: int) -> np.ndarray:
    """(m,) bool: faces of a component (across edges with two faces) with no consistent
    orientation, such as a Moebius strip."""
    m = Fw.shape[0]
    H = _half_edges(Fw)
    f = np.tile(np.arange(m), 3)
    key = np.minimum(H[:, 0], H[:, 1]) * n + np.maximum(H[:, 0], H[:, 1])
    order = np.argsort(key, kind="stable")
    key, H, f = key[order], H[order], f[order]
    _, start, cnt = np.unique(key, return_index=True, return_counts=True)
    a = start[cnt == 2]
    fa, fb = f[a], f[a + 1]
    same = H[a, 0] == H[a + 1, 0]  # both faces run the edge one way: opposite orientations
    rows = np.concatenate([fa, fa + m])
    cols = np.concatenate([np.where(same, fb + m, fb), np.where(same, fb, fb + m)])
    G = sp.coo_matrix((np.ones(rows.size, dtype=bool), (rows, cols)), shape=(2 * m, 2 * m))
    lab = connected_components(G, directed=False)[1]
    return lab[:m] == lab[m:]


def _unwound_loops(Fw: np.ndarray, n: int, edges: np.ndarray) -> tuple[list, list]:
    """Boundary ``edges`` (k, 2) left by the directed walks (faces wound inconsistently along
    them), as simple cycles running like most of their faces, and the other pieces' vertices."""
    adj = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    lab = connected_components(adj, directed=False)[1]
    deg = np.bincount(edges.ravel(), minlength=n)
    H = _half_edges(Fw)
    hkey = np.sort(H[:, 0] * n + H[:, 1])
    comp_of = lab[edges[:, 0]]
    cycles, pieces = [], []
    nbr: dict[int, list] = {}
    for u, v in edges.tolist():
        nbr.setdefault(u, []).append(v)
        nbr.setdefault(v, []).append(u)
    for c in np.unique(comp_of).tolist():
        vs = np.unique(edges[comp_of == c])
        if not np.all(deg[vs] == 2) or vs.size < 3:
            pieces.append(vs)
            continue
        loop, prev = [int(vs[0])], -1
        while len(loop) < vs.size:
            a, b = nbr[loop[-1]]
            nxt = b if a == prev else a
            prev = loop[-1]
            loop.append(nxt)
        loop = np.asarray(loop, dtype=np.int64)
        if 2 * np.count_nonzero(_in_sorted(loop * n + np.roll(loop, -1), hkey)) < loop.size:
            loop = loop[::-1].copy()
        cycles.append(loop)
    return cycles, pieces


def fill_holes(
    V: Any,
    F: Any,
    *,
    method: str = "lsm",
    max_hole: int | None = None,
    weld_seams: bool = True,
    density: float = 1.0,
    rng: Any = None,
) -> FilledMesh:
    """Close every boundary loop of a mesh: implant points, triangulate, complete (Section 5.3.1).

    Patches: docs/decisions.md#complete-holes-details; the default method:
    docs/decisions.md#complete-fill-holes. A loop is left open, and reported in
    ``open_loops``, when it is longer than ``max_hole``, is not one closed border, lies on a
    non-orientable surface, or when its fill would duplicate a face or give an edge more than
    two faces; borders whose faces are wound inconsistently are followed edge by edge.

    Parameters
    ----------
    V, F : (n, 3) array_like, (m, 3) array_like of int
    method : {"lsm", "li", "mc"}
        Completion of the implanted points on :data:`FAIR_RINGS` rings around them.
    max_hole : int, optional
        Leave loops with more edges open (e.g. a scan's border).
    weld_seams : bool
        Treat coincident border vertices as one, so that seams are not holes (the input faces
        keep their indices).
    density, rng
        Implanted points per loop edge length (refused above :data:`MAX_IMPLANTED`); seed.

    Returns
    -------
    FilledMesh
        Unpacks as ``(V_out, F_out)``: the input rows then the implanted points, the input faces
        unchanged then the new faces; ``n_loops``, ``n_filled`` and ``open_loops``.
    """
    V = as_points(V, "V")
    n = V.shape[0]
    F = as_faces(F, n, "F")
    check_choice(method, "method", INPAINT_METHODS)
    check_positive(density, "density")
    if max_hole is not None:
        check_positive(max_hole, "max_hole", integer=True)
    Fo = F
    if weld_seams:
        # border vertices are welded to their first coincident border copy for finding the
        # holes (a seam of duplicated vertices is no hole); coincident vertices inside the
        # surface (parts that touch) stay apart; the output keeps the input's face indices
        to = _seam_map(V, F, n)
        Fw = to[F]
        ok = (Fw[:, 0] != Fw[:, 1]) & (Fw[:, 1] != Fw[:, 2]) & (Fw[:, 2] != Fw[:, 0])
        Fw, Fo = Fw[ok], F[ok]
        if Fw.shape[0] == 0:
            raise InvalidInputError(
                "every face of the mesh collapses when its coincident border vertices are "
                "merged; there is no surface whose holes could be filled."
            )
    else:
        Fw = F
    check = _Checker(Fw, n)
    walks = [s for lp in boundary_loops(Fw, n) for s in _simple_loops(lp)]
    loops = [s for s in walks if check.loop_closed(s)]
    n_walked = len(loops)
    pieces: list = []
    if n_walked < len(walks):  # borders along which the faces are wound inconsistently
        B = np.sort(boundary_edges(Fw, n), axis=1)
        done = np.concatenate(
            [np.sort(np.column_stack([lp, np.roll(lp, -1)]), axis=1) for lp in loops]
            or [np.zeros((0, 2), dtype=np.int64)]
        )
        B = B[~_in_sorted(B[:, 0] * n + B[:, 1], np.unique(done[:, 0] * n + done[:, 1]))]
        more, pieces = _unwound_loops(Fw, n, B)
        loops += more
    copies = _loop_copies(loops, Fo, Fw, n)
    E = np.sort(np.concatenate([Fw[:, [0, 1]], Fw[:, [1, 2]], Fw[:, [2, 0]]]), axis=1)
    edge_keys = np.unique(E[:, 0] * n + E[:, 1])
    new_pts: list[np.ndarray] = []
    new_faces: list[np.ndarray] = []
    ctx = _Context(V, Fw, n, edge_keys)
    n_next = n
    todo, open_loops = [], [OpenLoop(pc, OPEN_NOT_CLOSED) for pc in pieces]
    bad_face = _non_orientable(Fw, n) if len(loops) > n_walked else None
    expected = 0.0
    for k, (loop, cp) in enumerate(zip(loops, copies)):
        L = loop.size
        if max_hole is not None and L > max_hole:
            open_loops.append(OpenLoop(cp, OPEN_MAX_HOLE))
            continue
        if k >= n_walked and bad_face[check.faces_on(loop)].any():
            open_loops.append(OpenLoop(cp, OPEN_NON_ORIENTABLE))
            continue
        P = V[loop]
        h = float(np.linalg.norm(P - np.roll(P, -1, axis=0), axis=1).mean()) / density
        todo.append((loop, cp, P, h))
        expected += _lattice_count(P, h)
    if expected > MAX_IMPLANTED:
        raise InvalidInputError(
            f"`density` = {density:g} would implant about {expected:,.0f} points into the "
            f"{len(todo)} hole(s) (at most {MAX_IMPLANTED:,}, about 20 GB of memory); lower "
            "`density` (1 spaces the points like the hole's border edges) or leave large holes "
            "open with `max_hole`."
        )
    for loop, cp, P, h in progress(todo, desc="holes", total=len(todo)):
        tri, new3 = _loop_patch(loop, P, h, ctx)
        new_ids = np.arange(n_next, n_next + new3.shape[0])
        faces_w = np.concatenate([loop, new_ids])[tri]  # already oriented against the loop
        why = check.problem(loop, faces_w)
        if why is not None:
            open_loops.append(OpenLoop(cp, why))
            continue
        check.add(faces_w)
        ctx.add_edges(faces_w)
        new_pts.append(new3)
        new_faces.append(np.concatenate([cp, new_ids])[tri])
        n_next += new3.shape[0]
    if not new_faces:
        return FilledMesh(V.copy(), F.copy(), len(loops) + len(pieces), open_loops)
    V_all = np.concatenate([V, *new_pts])
    F_all = np.concatenate([F, *new_faces]).astype(np.int64)
    if V_all.shape[0] > n:
        unknown = np.zeros(V_all.shape[0], dtype=bool)
        unknown[n:] = True
        with activity(f"completing {int(unknown.sum())} implanted points ({method})"):
            V_all[unknown] = _complete_near(V_all, F_all, unknown, method, rng)
    return FilledMesh(V_all, F_all, len(loops) + len(pieces), open_loops)


#: Graph rings of known vertices around the implanted points that take part in their completion:
#: exact for ``li`` (its equations reach two rings), a local version of ``lsm`` (whose soft
#: constraints couple the whole mesh, with an influence that fades within a few rings) and of
#: ``mc`` (patches of up to 64 vertices).
FAIR_RINGS = {"li": 2, "lsm": 4, "mc": 8}


def _complete_near(
    V: np.ndarray, F: np.ndarray, unknown: np.ndarray, method: str, rng
) -> np.ndarray:
    """Complete the ``unknown`` rows on the submesh within :data:`FAIR_RINGS` rings."""
    from ..graph import adjacency_matrix, k_ring

    N = V.shape[0]
    sub = k_ring(adjacency_matrix(F, N), np.flatnonzero(unknown), FAIR_RINGS[method])
    region = np.zeros(N, dtype=bool)
    region[sub] = True
    remap = np.full(N, -1, dtype=np.int64)
    remap[sub] = np.arange(sub.size)
    Fs = remap[F[region[F].all(axis=1)]]
    X = inpaint(V[sub], Fs, ~unknown[sub], method=method, rng=rng)
    return X[unknown[sub]]
