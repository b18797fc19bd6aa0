"""Halos of k-d tiles: the region holding every point a tile's own values read.

A reach is a list of kNN hops ``(k_1, k_2)``. The ``k``-th neighbour distance of a point within
any subset bounds the true one, so the halo width ``w`` (how far the own points' ``k_1``-NN balls
reach beyond the box) brings in every true neighbour; a second hop repeats this with the
neighbours' ``k_2``-NN balls measured in that region. Balls far larger than the median
(isolated outliers) are loaded one by one instead of widening ``w`` (:func:`_reach`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from .._errors import InvalidInputError
from .._threads import numba_threads
from ._common import SortedCloud, knn_grid
from ._tiles import load

__all__ = ["tile_job"]


def _protrusion(P: np.ndarray, r: np.ndarray, lo: np.ndarray, hi: np.ndarray, glo, ghi):
    """Per point, how far the ball ``B(P_i, r_i)`` reaches beyond the box ``[lo, hi]`` (sides on
    the global bounding box excepted: no point lies beyond them); (n,) >= 0."""
    out = np.zeros(P.shape[0])
    for a in range(3):  # one column at a time (a few 1-D passes instead of (n, 3) temporaries)
        if lo[a] > glo[a]:
            np.maximum(out, lo[a] - (P[:, a] - r), out=out)
        if hi[a] < ghi[a]:
            np.maximum(out, (P[:, a] + r) - hi[a], out=out)
    return out


def _reach(P, r, lo, hi, glo, ghi, w_min: float = 0.0):
    """Halo width ``w`` and the *stragglers* for the balls ``B(P_i, r_i)``: ``w`` covers the balls
    of the regular points (radius <= 3x the median radius), the stragglers (a few points with far
    larger balls, e.g. isolated outliers) are returned as balls ``(centres, radii)`` to load
    one by one, instead of widening the whole halo to the largest ball. Also returns which balls
    stick out of the box at all."""
    r = r * (1 + 1e-9)
    prot = _protrusion(P, r, lo, hi, glo, ghi) * (1 + 1e-9)
    if P.shape[0] == 0:
        return w_min, P[:0], r[:0], prot > 0
    med = float(np.median(r))
    regular = r <= 3.0 * med if med > 0 else np.ones(r.shape, dtype=bool)
    w = max(w_min, float(prot[regular].max(initial=0.0)))
    far = prot > w
    return w, P[far], r[far], prot > 0


def _region(spill, t, boxes, w, n_tiles, tag="", balls=None):
    """Tile ``t``'s own points first, then every other tile's points within ``w`` of its box or
    inside one of the ``balls`` ``(centres (s, 3), radii (s,))``."""
    from scipy.spatial import cKDTree

    core, cidx = load(spill, t, tag)
    lo, hi = boxes[t, 0] - w, boxes[t, 1] + w
    c, rad = balls if balls is not None else (np.zeros((0, 3)), np.zeros(0))
    parts = [core]
    for u in range(n_tiles):
        if u == t:
            continue
        blo, bhi = boxes[u]
        in_box = w > 0 and not (np.any(blo > hi) or np.any(bhi < lo))
        hit = np.all((c + rad[:, None] >= blo) & (c - rad[:, None] <= bhi), axis=1)
        if not in_box and not hit.any():
            continue
        xyz, _ = load(spill, u, tag)
        inside = np.all((xyz >= lo) & (xyz <= hi), axis=1) if in_box else np.zeros(len(xyz), bool)
        if hit.any() and len(xyz):
            # candidates: outside the widened box, inside the bounding box of the hitting balls
            ch, rh = c[hit], rad[hit]
            blo_b, bhi_b = (ch - rh[:, None]).min(axis=0), (ch + rh[:, None]).max(axis=0)
            rest = np.flatnonzero(~inside & np.all((xyz >= blo_b) & (xyz <= bhi_b), axis=1))
            if rest.size:
                tree = cKDTree(xyz[rest], balanced_tree=False, compact_nodes=False)
                found = tree.query_ball_point(ch, rh)
                sel = [np.asarray(f, dtype=np.int64) for f in found if len(f)]
                if sel:
                    inside[rest[np.concatenate(sel)]] = True
        if inside.any():
            parts.append(xyz[inside])
    return core, cidx, np.concatenate(parts) if len(parts) > 1 else core


def _own_knn(P: np.ndarray, m: int, k: int, workers, known=None):
    """Exact ``k``-NN (self excluded) of the first ``m`` points of ``P`` among all of ``P``.

    Returns ``dmean``, ``dlast`` of the ``m`` points, ``(radii, used)`` (the ``k2``-NN radius of any
    rows; the rows of the ``m`` points and all their neighbours) and ``(sc, nbr, n_zero)`` (sorted
    cloud, neighbour rows, points with a duplicate). ``known`` reuses a search among the own points
    for those whose ball lies inside the box (not flagged in ``edge``).
    """
    sc = SortedCloud.of(P)
    pos = np.empty(P.shape[0], dtype=np.int64)
    pos[sc.order] = np.arange(P.shape[0])

    def query(rows: np.ndarray, kk: int):
        # queries in Morton order (faster than scattered ones); results back in rows' order
        p = pos[rows]
        o = np.argsort(p)
        q = p[o]
        back = np.empty_like(o)
        back[o] = np.arange(o.size)
        with numba_threads(workers):
            nb = knn_grid(sc, kk, query=q, self_index=q)
        return nb, back

    idt = np.int32 if P.shape[0] < 2**31 else np.int64
    if known is None:
        if m == P.shape[0]:  # every point queries: the plain search (as rpca_scores runs it)
            with numba_threads(workers):
                nb = knn_grid(sc, k)
            back = pos
        else:
            nb, back = query(np.arange(m), k)
        dmean, dlast = nb.dmean[back], nb.dlast[back]
        nbr = sc.order[nb.idx[back]].astype(idt)
        n_zero = nb.n_zero
    else:
        dmean, dlast, nbr, n_zero, edge = known
        dmean, dlast, nbr = dmean.copy(), dlast.copy(), nbr.copy()
        rows = np.flatnonzero(edge)
        nb = None
        if rows.size:
            nb, back = query(rows, k)
            dmean[rows], dlast[rows] = nb.dmean[back], nb.dlast[back]
            nbr[rows] = sc.order[nb.idx[back]]

    def radii(rows: np.ndarray, k2: int) -> np.ndarray:
        r, at = query(rows, k2)
        return r.dlast[at]

    def used() -> np.ndarray:
        # (with ``known``, the other points' neighbours are own points, marked already)
        mark = np.zeros(P.shape[0], dtype=bool)
        mark[:m] = True
        if nb is not None:
            mark[sc.order[nb.idx.ravel()]] = True
        return np.flatnonzero(mark)

    return dmean, dlast, (radii, used), (sc, nbr, n_zero)


def _halo_region(spill, t, boxes, gbox, hops, workers, tag=""):
    """Own points, their rows, the region (own points first), ``dmean`` (m,): the mean distance
    of the own points to their ``hops[0]`` nearest region points (self excluded), the halo
    width, with a halo wide enough for the reach ``hops`` (module docstring), and ``knn``: the
    region's sorted cloud, the own points' ``hops[0]`` nearest neighbours (rows of the region)
    and the number of own points with a duplicate (see :func:`_own_knn`). The neighbour
    searches are the compiled exact grid search of the untiled filters."""
    from scipy.spatial import cKDTree

    n_tiles = boxes.shape[0]
    glo, ghi = gbox
    lo, hi = boxes[t]
    k1 = int(hops[0])
    core, cidx = load(spill, t, tag)
    m = core.shape[0]
    if m == 0:
        return core, cidx, core, np.empty(0), 0.0, None
    known = None
    if m > k1:  # k1-NN radii among the own points
        d0, r0, _, (_, nbr0, nz0) = _own_knn(core, m, k1, workers)
    else:  # too few own points: widen until the region has k1 + 1 points, radii in it
        w = max(float(np.max(ghi - glo)) / 64.0, np.finfo(float).tiny)
        while True:
            _, _, R = _region(spill, t, boxes, w, n_tiles, tag)
            if R.shape[0] > k1 or w > 4.0 * float(np.max(ghi - glo)):
                break
            w *= 2.0
        d0, _ = cKDTree(R).query(core, min(k1 + 1, R.shape[0]), workers=workers)
        r0 = d0.reshape(m, -1)[:, -1]
    w, bc, br, edge = _reach(core, r0, lo, hi, glo, ghi)
    if m > k1:  # balls inside the box hold only own points: those neighbours are final
        known = (d0, r0, nbr0, nz0, edge)
    core, cidx, R = _region(spill, t, boxes, w, n_tiles, tag, (bc, br))
    if R.shape[0] < k1 + 1:
        raise InvalidInputError(
            f"`k` = {k1} neighbours need at least {k1 + 1} points; the cloud has fewer."
        )
    dmean, dlast, (radii, used), knn = _own_knn(R, m, k1, workers, known)
    if len(hops) > 2:  # pragma: no cover - internal: reaches of at most two hops
        raise ValueError("reach of at most two hops")
    if len(hops) == 2:
        k2 = int(hops[1])
        # second hop: the k2-NN balls of the own points and their neighbours, measured in this
        # region (an upper bound of the true radii); reload once if some stick out
        js = used()
        if R.shape[0] < k2 + 1:
            w2, c2, r2 = math.inf, R[:0], np.zeros(0)
        else:
            if k2 == k1:  # the own points' k2-NN radii are their k1-NN radii, known already
                own = js < m
                rj = np.empty(js.size)
                rj[own] = dlast[js[own]]
                rj[~own] = radii(js[~own], k2)
            else:
                rj = radii(js, k2)
            w2, c2, r2, _ = _reach(R[js], rj, lo, hi, glo, ghi, w_min=w)
        if w2 > w or len(r2):
            w = w2
            balls = (np.concatenate([bc, c2]), np.concatenate([br, r2]))
            # the own points' k1-NN were exact already: ``dmean`` stands
            core, cidx, R = _region(spill, t, boxes, w, n_tiles, tag, balls)
            bc, br = balls
            # own points whose neighbours may lie in the halo are searched again in the new R
            knn = _own_knn(R, m, k1, workers, known)[3]
    return core, cidx, R, dmean, float(w), knn


def tile_job(
    spill: str,
    t: int,
    boxes: np.ndarray,
    gbox: np.ndarray,
    hops: tuple[int, ...],
    fn: Callable[..., dict],
    params: dict,
    n_threads: int | None,
    tag: str = "",
) -> dict:
    """One Dask task: ``fn(R, m, dmean, workers=..., **params)`` on tile ``t``'s region ``R`` (own
    points first, ``m`` of them; ``dmean`` their mean kNN distance), halo from ``hops``.
    ``fn`` returns per-own-point arrays (and scalars); ``idx`` (the own points' input rows),
    ``n_region``, ``w`` and ``time_s`` are added."""
    t0 = time.perf_counter()
    workers = n_threads if n_threads is not None else -1
    core, cidx, R, dmean, w, knn = _halo_region(spill, t, boxes, gbox, hops, workers, tag)
    m = core.shape[0]
    out: dict = {}
    if m:
        kw = {"knn": (*knn, dmean)} if getattr(fn, "takes_knn", False) else {}
        out = fn(R, m, dmean, workers=workers, **kw, **params)
    out.update(
        idx=cidx,
        n_region=int(R.shape[0]) if m else 0,
        w=w,
        time_s=time.perf_counter() - t0,
    )
    return out
