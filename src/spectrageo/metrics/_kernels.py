"""Numba kernels: exact point-to-triangle distances over candidate lists."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _seg_sqdist(px, py, pz, ax, ay, az, bx, by, bz):  # pragma: no cover - jitted
    """Squared distance from p to segment [a, b] (a point when a == b); returns (d2, t)."""
    ux, uy, uz = bx - ax, by - ay, bz - az
    wx, wy, wz = px - ax, py - ay, pz - az
    uu = ux * ux + uy * uy + uz * uz
    t = 0.0
    if uu > 0.0:
        t = (wx * ux + wy * uy + wz * uz) / uu
        if t < 0.0:
            t = 0.0
        elif t > 1.0:
            t = 1.0
    dx, dy, dz = wx - t * ux, wy - t * uy, wz - t * uz
    return dx * dx + dy * dy + dz * dz, t


@numba.njit(cache=True)
def _closest_on_edges(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):  # pragma: no cover
    """Closest point of the union of the triangle's three edges, as barycentric weights."""
    d_ab, t_ab = _seg_sqdist(px, py, pz, ax, ay, az, bx, by, bz)
    d_bc, t_bc = _seg_sqdist(px, py, pz, bx, by, bz, cx, cy, cz)
    d_ca, t_ca = _seg_sqdist(px, py, pz, cx, cy, cz, ax, ay, az)
    if d_ab <= d_bc and d_ab <= d_ca:
        return 1.0 - t_ab, t_ab, 0.0
    if d_bc <= d_ca:
        return 0.0, 1.0 - t_bc, t_bc
    return t_ca, 0.0, 1.0 - t_ca


@numba.njit(cache=True)
def closest_point_on_triangle(
    px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz
):  # pragma: no cover - jitted
    """Closest point of triangle (a, b, c) to p as barycentric weights (Ericson, Sec. 5.1.5).

    Degenerate triangles, and those whose terms round to zero against the distance, use their edges.
    """
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    # Gram determinant |ab x ac|^2 = |ab|^2 |ac|^2 - (ab.ac)^2
    nx = aby * acz - abz * acy
    ny = abz * acx - abx * acz
    nz = abx * acy - aby * acx
    if nx * nx + ny * ny + nz * nz <= 0.0:
        return _closest_on_edges(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz)
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0  # vertex a
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0  # vertex b
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        if not d1 - d3 > 0.0:  # d1 - d3 = |ab|^2, lost to rounding
            return _closest_on_edges(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz)
        v = d1 / (d1 - d3)
        return 1.0 - v, v, 0.0  # edge ab
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0  # vertex c
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        if not d2 - d6 > 0.0:  # = |ac|^2, lost to rounding
            return _closest_on_edges(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz)
        w = d2 / (d2 - d6)
        return 1.0 - w, 0.0, w  # edge ac
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        if not (d4 - d3) + (d5 - d6) > 0.0:  # = |bc|^2, lost to rounding
            return _closest_on_edges(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz)
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1.0 - w, w  # edge bc
    if not va + vb + vc > 0.0:  # = |ab x ac|^2 in exact arithmetic
        return _closest_on_edges(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return 1.0 - v - w, v, w  # interior


@numba.njit(cache=True, inline="always")
def _tri_sqdist(Q, i, V, F, t):  # pragma: no cover - jitted
    a, b, c = F[t, 0], F[t, 1], F[t, 2]
    px, py, pz = Q[i, 0], Q[i, 1], Q[i, 2]
    u, v, w = closest_point_on_triangle(
        px, py, pz,
        V[a, 0], V[a, 1], V[a, 2],
        V[b, 0], V[b, 1], V[b, 2],
        V[c, 0], V[c, 1], V[c, 2],
    )  # fmt: skip
    x = u * V[a, 0] + v * V[b, 0] + w * V[c, 0] - px
    y = u * V[a, 1] + v * V[b, 1] + w * V[c, 1] - py
    z = u * V[a, 2] + v * V[b, 2] + w * V[c, 2] - pz
    return x * x + y * y + z * z


@numba.njit(cache=True, parallel=True)
def best_over_candidates(
    Q: np.ndarray,
    rows: np.ndarray,
    indptr: np.ndarray,
    cand: np.ndarray,
    V: np.ndarray,
    F: np.ndarray,
    best_d2: np.ndarray,
    best_t: np.ndarray,
) -> None:  # pragma: no cover - jitted
    """For query ``rows[r]``, test triangles ``cand[indptr[r]:indptr[r+1]]`` (entries < 0 skipped)
    and lower ``best_d2`` / ``best_t`` in place where a closer triangle is found."""
    for r in numba.prange(rows.shape[0]):
        i = rows[r]
        bd = best_d2[i]
        bt = best_t[i]
        for k in range(indptr[r], indptr[r + 1]):
            t = cand[k]
            if t < 0:
                continue
            d = _tri_sqdist(Q, i, V, F, t)
            if d < bd or (d == bd and t < bt):
                bd = d
                bt = t
        best_d2[i] = bd
        best_t[i] = bt


@numba.njit(cache=True, parallel=True)
def closest_points(
    Q: np.ndarray, tri: np.ndarray, V: np.ndarray, F: np.ndarray
) -> np.ndarray:  # pragma: no cover - jitted
    """Closest point of triangle ``tri[i]`` to ``Q[i]``, shape (n, 3)."""
    out = np.empty_like(Q)
    for i in numba.prange(Q.shape[0]):
        t = tri[i]
        a, b, c = F[t, 0], F[t, 1], F[t, 2]
        u, v, w = closest_point_on_triangle(
            Q[i, 0], Q[i, 1], Q[i, 2],
            V[a, 0], V[a, 1], V[a, 2],
            V[b, 0], V[b, 1], V[b, 2],
            V[c, 0], V[c, 1], V[c, 2],
        )  # fmt: skip
        for j in range(3):
            out[i, j] = u * V[a, j] + v * V[b, j] + w * V[c, j]
    return out


# --------------------------------------------------------------------------- bounding-volume hierarchy
@numba.njit(cache=True)
def build_bvh(
    tmin: np.ndarray, tmax: np.ndarray, cent: np.ndarray, leaf_size: int
):  # pragma: no cover
    """Bounding-box tree over triangles, split at the centroid bounds' longest-axis midpoint (else median)."""
    m = cent.shape[0]
    order = np.arange(m)
    max_nodes = 2 * m + 1
    nmin = np.empty((max_nodes, 3))
    nmax = np.empty((max_nodes, 3))
    left = np.full(max_nodes, -1, dtype=np.int64)
    right = np.full(max_nodes, -1, dtype=np.int64)
    start = np.zeros(max_nodes, dtype=np.int64)
    count = np.zeros(max_nodes, dtype=np.int64)
    depth = np.zeros(max_nodes, dtype=np.int64)
    st_node = np.empty(max_nodes, dtype=np.int64)
    st_s = np.empty(max_nodes, dtype=np.int64)
    st_e = np.empty(max_nodes, dtype=np.int64)
    sp = 0
    st_node[0], st_s[0], st_e[0] = 0, 0, m
    sp = 1
    n_nodes = 1
    max_depth = 0
    while sp > 0:
        sp -= 1
        node, s, e = st_node[sp], st_s[sp], st_e[sp]
        if depth[node] > max_depth:
            max_depth = depth[node]
        lo0 = lo1 = lo2 = np.inf
        hi0 = hi1 = hi2 = -np.inf
        c0 = c1 = c2 = np.inf
        d0 = d1 = d2 = -np.inf
        for k in range(s, e):
            t = order[k]
            lo0 = min(lo0, tmin[t, 0])
            lo1 = min(lo1, tmin[t, 1])
            lo2 = min(lo2, tmin[t, 2])
            hi0 = max(hi0, tmax[t, 0])
            hi1 = max(hi1, tmax[t, 1])
            hi2 = max(hi2, tmax[t, 2])
            c0 = min(c0, cent[t, 0])
            c1 = min(c1, cent[t, 1])
            c2 = min(c2, cent[t, 2])
            d0 = max(d0, cent[t, 0])
            d1 = max(d1, cent[t, 1])
            d2 = max(d2, cent[t, 2])
        nmin[node, 0], nmin[node, 1], nmin[node, 2] = lo0, lo1, lo2
        nmax[node, 0], nmax[node, 1], nmax[node, 2] = hi0, hi1, hi2
        e0, e1, e2 = d0 - c0, d1 - c1, d2 - c2
        axis, ext, clo, chi = 0, e0, c0, d0
        if e1 > ext:
            axis, ext, clo, chi = 1, e1, c1, d1
        if e2 > ext:
            axis, ext, clo, chi = 2, e2, c2, d2
        if e - s <= leaf_size or ext <= 0.0:
            start[node] = s
            count[node] = e - s
            continue
        split = 0.5 * (clo + chi)
        i, j = s, e - 1
        while i <= j:
            if cent[order[i], axis] < split:
                i += 1
            else:
                tmp = order[i]
                order[i] = order[j]
                order[j] = tmp
                j -= 1
        mid = i
        if mid == s or mid == e:
            seg = order[s:e].copy()
            key = np.empty(e - s)
            for k in range(e - s):
                key[k] = cent[seg[k], axis]
            o = np.argsort(key)
            for k in range(e - s):
                order[s + k] = seg[o[k]]
            mid = (s + e) // 2
        l, r = n_nodes, n_nodes + 1
        n_nodes += 2
        left[node], right[node] = l, r
        depth[l] = depth[node] + 1
        depth[r] = depth[node] + 1
        st_node[sp], st_s[sp], st_e[sp] = l, s, mid
        sp += 1
        st_node[sp], st_s[sp], st_e[sp] = r, mid, e
        sp += 1
    return order, nmin, nmax, left, right, start, count, n_nodes, max_depth


@numba.njit(cache=True, inline="always")
def _box_sqdist(Q, i, nmin, nmax, node):  # pragma: no cover - jitted
    d = 0.0
    for j in range(3):
        q = Q[i, j]
        if q < nmin[node, j]:
            d += (nmin[node, j] - q) ** 2
        elif q > nmax[node, j]:
            d += (q - nmax[node, j]) ** 2
    return d


@numba.njit(cache=True, parallel=True)
def bvh_query(
    Q, V, F, order, nmin, nmax, left, right, start, count, max_depth, best_d2, best_t
):  # pragma: no cover - jitted
    """Exact closest triangle of every point (BVH depth-first); updates ``best_d2``, ``best_t``."""
    for i in numba.prange(Q.shape[0]):
        stack = np.empty(2 * max_depth + 4, dtype=np.int64)
        bd = best_d2[i]
        bt = best_t[i]
        stack[0] = 0
        sp = 1
        while sp > 0:
            sp -= 1
            node = stack[sp]
            if _box_sqdist(Q, i, nmin, nmax, node) > bd:
                continue
            if count[node] > 0:
                for k in range(start[node], start[node] + count[node]):
                    t = order[k]
                    d = _tri_sqdist(Q, i, V, F, t)
                    if d < bd or (d == bd and t < bt):
                        bd = d
                        bt = t
                continue
            l, r = left[node], right[node]
            dl = _box_sqdist(Q, i, nmin, nmax, l)
            dr = _box_sqdist(Q, i, nmin, nmax, r)
            if dl <= dr:  # push the farther child first so the nearer one is visited first
                if dr <= bd:
                    stack[sp] = r
                    sp += 1
                if dl <= bd:
                    stack[sp] = l
                    sp += 1
            else:
                if dl <= bd:
                    stack[sp] = l
                    sp += 1
                if dr <= bd:
                    stack[sp] = r
                    sp += 1
        best_d2[i] = bd
        best_t[i] = bt
