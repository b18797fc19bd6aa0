"""Hole filling with unknown connectivity (thesis Section 5.3.1, last scenario)."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import Delaunay

from .._errors import InvalidInputError
from .._progress import activity, progress
from .._validation import as_faces, as_points, check_choice, check_positive
from ..geometry import boundary_edges, boundary_loops, weld
from ..geometry.primitives import _normalize_rows
from .static import INPAINT_METHODS, inpaint

__all__ = ["DP_MAX_LOOP", "FAIR_RINGS", "MAX_IMPLANTED", "fill_holes"]

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


def _chords_ok(tri: np.ndarray, loop: np.ndarray, edge_keys: np.ndarray, n: int) -> bool:
    """No patch chord between loop vertices may already be a mesh edge."""
    L = loop.size
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    e = e[(e < L).all(axis=1)]
    d = np.abs(e[:, 0] - e[:, 1])
    e = e[(d != 1) & (d != L - 1)]
    if e.size == 0:
        return True
    g = np.sort(loop[e], axis=1)
    return not _in_sorted(g[:, 0] * n + g[:, 1], edge_keys).any()


def _fan_patch(P: np.ndarray):
    """Last resort: a fan around the loop's centroid."""
    L = P.shape[0]
    i = np.arange(L)
    return np.column_stack([i, (i + 1) % L, np.full(L, L)]), P.mean(axis=0)[None]


class _Context:
    """Mesh data a loop patch needs (faces' directed rotations built on first use)."""

    def __init__(self, V: np.ndarray, F: np.ndarray, n: int, edge_keys: np.ndarray):
        self.V, self.F, self.n, self.edge_keys = V, F, n, edge_keys
        self._faces = None

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
    if got is not None and not _chords_ok(got[0], loop, ctx.edge_keys, n):
        got = None
    if got is None:
        g = np.sort(np.stack(np.meshgrid(loop, loop, indexing="ij"), axis=-1), axis=-1)
        forbid = _in_sorted(g[..., 0] * n + g[..., 1], ctx.edge_keys) & (g[..., 0] >= 0)
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


def fill_holes(
    V: Any,
    F: Any,
    *,
    method: str = "lsm",
    max_hole: int | None = None,
    weld_seams: bool = True,
    density: float = 1.0,
    rng: Any = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Close every boundary loop of a mesh: implant points, triangulate, complete (Section 5.3.1).

    Patches: docs/decisions.md#complete-holes-details; the default method:
    docs/decisions.md#complete-fill-holes.

    Parameters
    ----------
    V, F : (n, 3) array_like, (m, 3) array_like of int
    method : {"lsm", "li", "mc"}
        Completion of the implanted points on :data:`FAIR_RINGS` rings around them.
    max_hole : int, optional
        Leave loops with more edges open (e.g. a scan's border).
    weld_seams : bool
        Treat coincident border vertices as one, so that seams are not holes.
    density, rng
        Implanted points per loop edge length (refused above :data:`MAX_IMPLANTED`); seed.

    Returns
    -------
    V_out : (n + p, 3) ndarray
        The input rows, then the implanted points.
    F_out : (m' + q, 3) int64 ndarray
        The input faces (re-indexed when welded), then the new faces.
    """
    V = as_points(V, "V")
    n = V.shape[0]
    F = as_faces(F, n, "F")
    check_choice(method, "method", INPAINT_METHODS)
    check_positive(density, "density")
    if max_hole is not None:
        check_positive(max_hole, "max_hole", integer=True)
    if weld_seams:
        # only border vertices are welded (to their first coincident border copy): a seam of
        # duplicated vertices closes, while coincident vertices inside the surface (parts that
        # touch) stay apart, as in the input
        onb = np.zeros(n, dtype=bool)
        onb[boundary_edges(F, n).ravel()] = True
        if onb.any():
            g = weld(V, F).index_map
            rep = np.full(int(g.max()) + 1, -1, dtype=np.int64)
            order = np.flatnonzero(onb)[::-1]
            rep[g[order]] = order  # first border vertex of each group
            to = np.where(onb, rep[g], np.arange(n))
            F = to[F]
            F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 2] != F[:, 0])]
            if F.shape[0] == 0:
                raise InvalidInputError("`F` has no face left after welding coincident vertices.")
    loops = [s for lp in boundary_loops(F, n) for s in _simple_loops(lp)]
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    edge_keys = np.unique(E[:, 0] * n + E[:, 1])
    new_pts: list[np.ndarray] = []
    new_faces: list[np.ndarray] = []
    ctx = _Context(V, F, n, edge_keys)
    n_next = n
    todo = []
    expected = 0.0
    for loop in loops:
        L = loop.size
        if L < 3 or (max_hole is not None and L > max_hole):
            continue
        P = V[loop]
        h = float(np.linalg.norm(P - np.roll(P, -1, axis=0), axis=1).mean()) / density
        todo.append((loop, P, h))
        expected += _lattice_count(P, h)
    if expected > MAX_IMPLANTED:
        raise InvalidInputError(
            f"`density` = {density:g} would implant about {expected:,.0f} points into the "
            f"{len(todo)} hole(s) (at most {MAX_IMPLANTED:,}, about 20 GB of memory); lower "
            "`density` (1 spaces the points like the hole's border edges) or leave large holes "
            "open with `max_hole`."
        )
    for loop, P, h in progress(todo, desc="holes", total=len(todo)):
        tri, new3 = _loop_patch(loop, P, h, ctx)
        ids = np.concatenate([loop, np.arange(n_next, n_next + new3.shape[0])])
        new_pts.append(new3)
        new_faces.append(ids[tri])  # already oriented against the loop
        n_next += new3.shape[0]
    if not new_faces:
        return V.copy(), F.copy()
    V_all = np.concatenate([V, *new_pts])
    F_all = np.concatenate([F, *new_faces]).astype(np.int64)
    if V_all.shape[0] > n:
        # unreferenced original rows (welded duplicates) are known: they stay as they are
        unknown = np.zeros(V_all.shape[0], dtype=bool)
        unknown[n:] = True
        with activity(f"completing {int(unknown.sum())} implanted points ({method})"):
            V_all[unknown] = _complete_near(V_all, F_all, unknown, method, rng)
    return V_all, F_all


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
