"""Supernodal sparse Cholesky ``K = P^T L L^T P`` with a fixed order of floating-point operations,
for the anchored Laplacian normal equations of Eq. 5.51, 5.54 (docs/decisions.md#deterministic-decoders).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from numba import njit

from .._errors import InvalidInputError
from ._amd import _canonical_csr, fill_reducing_order

#: columns of a supernode factorised as one panel by the blocked dense Cholesky
_PANEL = 64
#: rows of the output held while a dense update streams its inner dimension
_ROW_BLOCK = 256
#: right-hand sides up to which the solves gather each supernode's rows into a buffer
_FEW_RHS = 8


# ----------------------------------------------------------------------------- symbolic
@njit(cache=True)
def _etree(n, indptr, indices, perm, iperm):  # pragma: no cover - jitted
    """Elimination tree of ``P K P^T`` (Liu, path compression); ``parent[j] = -1`` at roots."""
    parent = np.full(n, -1, np.int64)
    anc = np.full(n, -1, np.int64)
    for k in range(n):
        r = perm[k]
        for p in range(indptr[r], indptr[r + 1]):
            i = iperm[indices[p]]
            while i != -1 and i < k:
                nxt = anc[i]
                anc[i] = k
                if nxt == -1:
                    parent[i] = k
                i = nxt
    return parent


@njit(cache=True)
def _postorder(parent):  # pragma: no cover - jitted
    """Depth-first postorder of a forest, children ascending; ``post[k]``: node at ``k``."""
    n = parent.size
    head = np.full(n, -1, np.int64)
    nxt = np.full(n, -1, np.int64)
    for j in range(n - 1, -1, -1):
        p = parent[j]
        if p != -1:
            nxt[j] = head[p]
            head[p] = j
    post = np.empty(n, np.int64)
    stack = np.empty(n, np.int64)
    k = 0
    for r in range(n):
        if parent[r] != -1:
            continue
        top = 0
        stack[0] = r
        while top >= 0:
            p = stack[top]
            c = head[p]
            if c == -1:
                top -= 1
                post[k] = p
                k += 1
            else:
                head[p] = nxt[c]
                top += 1
                stack[top] = c
    return post


@njit(cache=True)
def _colcounts(n, indptr, indices, perm, iperm, parent):  # pragma: no cover - jitted
    """Entries of every column of ``L``, diagonal included (row subtrees)."""
    cc = np.ones(n, np.int64)
    flag = np.full(n, -1, np.int64)
    for k in range(n):
        flag[k] = k
        r = perm[k]
        for p in range(indptr[r], indptr[r + 1]):
            i = iperm[indices[p]]
            if i > k:
                continue
            while flag[i] != k:
                cc[i] += 1
                flag[i] = k
                i = parent[i]
    return cc


@njit(cache=True)
def _supernodes(n, parent, cc):  # pragma: no cover - jitted
    """First column of every relaxed supernode (and ``n``) of a postordered tree: fundamental
    supernodes, then merges into the parent up to 4 columns, or 16 and 50 % zeros, 48 and 10 %, any
    size and 5 %.
    """
    first = np.empty(n + 1, np.int64)
    ns = 0
    for j in range(n):
        if j == 0 or not (parent[j - 1] == j and cc[j - 1] == cc[j] + 1):
            first[ns] = j
            ns += 1
    first[ns] = n
    # fundamental supernode statistics
    ncol = np.empty(ns, np.int64)
    nrow = np.empty(ns, np.int64)
    nnz = np.empty(ns, np.float64)
    spar = np.full(ns, -1, np.int64)
    sup = np.empty(n, np.int64)
    for s in range(ns):
        for j in range(first[s], first[s + 1]):
            sup[j] = s
    for s in range(ns):
        ncol[s] = first[s + 1] - first[s]
        nrow[s] = cc[first[s]]
        t = 0.0
        for j in range(first[s], first[s + 1]):
            t += cc[j]
        nnz[s] = t
        p = parent[first[s + 1] - 1]
        if p != -1:
            spar[s] = sup[p]
    # relaxed amalgamation: merge s into the group that starts at s + 1
    gcol = ncol.copy()
    grow = nrow.copy()
    gnnz = nnz.copy()
    merged = np.zeros(ns, np.bool_)  # merged[s]: s and s + 1 are in one group
    for s in range(ns - 2, -1, -1):
        if spar[s] != s + 1:
            continue
        c = ncol[s] + gcol[s + 1]
        r = ncol[s] + grow[s + 1]
        total = c * r - c * (c - 1) // 2
        z = (total - (nnz[s] + gnnz[s + 1])) / total
        if c <= 4 or (c <= 16 and z < 0.5) or (c <= 48 and z < 0.1) or z < 0.05:
            merged[s] = True
            gcol[s] = c
            grow[s] = r
            gnnz[s] = nnz[s] + gnnz[s + 1]
    out = np.empty(ns + 1, np.int64)
    m = 0
    for s in range(ns):
        if s == 0 or not merged[s - 1]:
            out[m] = first[s]
            m += 1
    out[m] = n
    return out[: m + 1].copy()


@njit(cache=True)
def _super_rows(n, indptr, indices, perm, iperm, parent, sfirst):  # pragma: no cover - jitted
    """Row pattern of every supernode: its own columns, then the rows below, ascending."""
    ns = sfirst.size - 1
    sup = np.empty(n, np.int64)
    for s in range(ns):
        for j in range(sfirst[s], sfirst[s + 1]):
            sup[j] = s
    spar = np.full(ns, -1, np.int64)
    for s in range(ns):
        p = parent[sfirst[s + 1] - 1]
        if p != -1:
            spar[s] = sup[p]
    flag = np.full(ns, -1, np.int64)
    cnt = np.zeros(ns + 1, np.int64)
    for k in range(n):
        sk = sup[k]
        flag[sk] = k
        cnt[sk + 1] += 1
        r = perm[k]
        for p in range(indptr[r], indptr[r + 1]):
            i = iperm[indices[p]]
            if i > k:
                continue
            s = sup[i]
            while flag[s] != k:
                flag[s] = k
                cnt[s + 1] += 1
                s = spar[s]
    for s in range(ns):
        cnt[s + 1] += cnt[s]
    Lpi = cnt.copy()
    Ls = np.empty(Lpi[ns], np.int64)
    flag[:] = -1
    for k in range(n):
        sk = sup[k]
        flag[sk] = k
        Ls[cnt[sk]] = k
        cnt[sk] += 1
        r = perm[k]
        for p in range(indptr[r], indptr[r + 1]):
            i = iperm[indices[p]]
            if i > k:
                continue
            s = sup[i]
            while flag[s] != k:
                flag[s] = k
                Ls[cnt[s]] = k
                cnt[s] += 1
                s = spar[s]
    return sup, Lpi, Ls


@njit(cache=True)
def _update_workspace(sfirst, sup, Lpi, Ls):  # pragma: no cover - jitted
    """Largest ``rows x columns`` block one supernode sends to an ancestor."""
    ns = sfirst.size - 1
    big = 0
    for d in range(ns):
        nc = sfirst[d + 1] - sfirst[d]
        p0 = Lpi[d]
        nr = Lpi[d + 1] - p0
        i = nc
        while i < nr:
            s = sup[Ls[p0 + i]]
            e = i
            while e < nr and sup[Ls[p0 + e]] == s:
                e += 1
            size = (nr - i) * (e - i)
            if size > big:
                big = size
            i = e
    return big


# ----------------------------------------------------------------------------- dense kernels
@njit(cache=True)
def _gemm_nt_sub(C, c0, ldc, A, a0, lda, B, b0, ldb, m, n, kk, i_lo):  # pragma: no cover
    """``C[i, j] -= sum_k A[i, k] B[j, k]`` on column-major flat blocks (``i_lo``: lower trapezoid),
    each entry updated with ``k`` ascending whatever the blocking; rows in blocks of
    :data:`_ROW_BLOCK`, the innermost loop over independent rows.
    """
    j = 0
    while j < n:
        w = min(4, n - j)
        ib = j if i_lo else 0
        while ib < m:
            ie = min(m, ib + _ROW_BLOCK)
            if w == 4:
                _update4(C, c0 + ib + j * ldc, ldc, A, a0 + ib, lda, B, b0 + j, ldb, ie - ib, kk)
            else:
                for jj in range(j, j + w):
                    _update1(C, c0 + ib + jj * ldc, A, a0 + ib, lda, B, b0 + jj, ldb, ie - ib, kk)
            ib = ie
        j += w


@njit(cache=True, inline="always")
def _update4(C, c0, ldc, A, a0, lda, B, b0, ldb, m, kk):  # pragma: no cover - jitted
    """Four columns of :func:`_gemm_nt_sub` over ``m`` rows."""
    u0 = C[c0 : c0 + m]
    u1 = C[c0 + ldc : c0 + ldc + m]
    u2 = C[c0 + 2 * ldc : c0 + 2 * ldc + m]
    u3 = C[c0 + 3 * ldc : c0 + 3 * ldc + m]
    k = 0
    while k + 4 <= kk:
        pb = b0 + k * ldb
        x0, x1, x2, x3 = B[pb], B[pb + 1], B[pb + 2], B[pb + 3]
        pb += ldb
        y0, y1, y2, y3 = B[pb], B[pb + 1], B[pb + 2], B[pb + 3]
        pb += ldb
        z0, z1, z2, z3 = B[pb], B[pb + 1], B[pb + 2], B[pb + 3]
        pb += ldb
        t0, t1, t2, t3 = B[pb], B[pb + 1], B[pb + 2], B[pb + 3]
        pa = a0 + k * lda
        va = A[pa : pa + m]
        vb = A[pa + lda : pa + lda + m]
        vc = A[pa + 2 * lda : pa + 2 * lda + m]
        vd = A[pa + 3 * lda : pa + 3 * lda + m]
        for i in range(m):
            a = va[i]
            b = vb[i]
            c = vc[i]
            d = vd[i]
            u0[i] = u0[i] - a * x0 - b * y0 - c * z0 - d * t0
            u1[i] = u1[i] - a * x1 - b * y1 - c * z1 - d * t1
            u2[i] = u2[i] - a * x2 - b * y2 - c * z2 - d * t2
            u3[i] = u3[i] - a * x3 - b * y3 - c * z3 - d * t3
        k += 4
    while k < kk:
        pb = b0 + k * ldb
        x0, x1, x2, x3 = B[pb], B[pb + 1], B[pb + 2], B[pb + 3]
        pa = a0 + k * lda
        va = A[pa : pa + m]
        for i in range(m):
            a = va[i]
            u0[i] -= a * x0
            u1[i] -= a * x1
            u2[i] -= a * x2
            u3[i] -= a * x3
        k += 1


@njit(cache=True, inline="always")
def _update1(C, c0, A, a0, lda, B, b0, ldb, m, kk):  # pragma: no cover - jitted
    """One column of :func:`_gemm_nt_sub` over ``m`` rows."""
    u0 = C[c0 : c0 + m]
    k = 0
    while k + 4 <= kk:
        pb = b0 + k * ldb
        x0 = B[pb]
        y0 = B[pb + ldb]
        z0 = B[pb + 2 * ldb]
        t0 = B[pb + 3 * ldb]
        pa = a0 + k * lda
        va = A[pa : pa + m]
        vb = A[pa + lda : pa + lda + m]
        vc = A[pa + 2 * lda : pa + 2 * lda + m]
        vd = A[pa + 3 * lda : pa + 3 * lda + m]
        for i in range(m):
            u0[i] = u0[i] - va[i] * x0 - vb[i] * y0 - vc[i] * z0 - vd[i] * t0
        k += 4
    while k < kk:
        x0 = B[b0 + k * ldb]
        pa = a0 + k * lda
        va = A[pa : pa + m]
        for i in range(m):
            u0[i] -= va[i] * x0
        k += 1


@njit(cache=True)
def _factor_block(X, x0, ld, nrow, ncol):  # pragma: no cover - jitted
    """Left-looking blocked Cholesky ``[L11; L21]`` of the column-major ``nrow x ncol`` block at
    ``X[x0]`` in panels of :data:`_PANEL`; returns the column of a non-positive pivot, or -1.
    """
    j0 = 0
    while j0 < ncol:
        j1 = min(ncol, j0 + _PANEL)
        if j0 > 0:
            _gemm_nt_sub(
                X,
                x0 + j0 + j0 * ld,
                ld,
                X,
                x0 + j0,
                ld,
                X,
                x0 + j0,
                ld,
                nrow - j0,
                j1 - j0,
                j0,
                True,
            )
        for j in range(j0, j1):
            pj = x0 + j * ld
            d = X[pj + j]
            if not d > 0.0 or not math.isfinite(d):
                return j
            piv = math.sqrt(d)
            X[pj + j] = piv
            below = X[pj + j + 1 : pj + nrow]
            for i in range(nrow - j - 1):
                below[i] = below[i] / piv
            for c in range(j + 1, j1):
                f = X[pj + c]
                src = X[pj + c : pj + nrow]
                dst = X[x0 + c * ld + c : x0 + c * ld + nrow]
                for i in range(nrow - c):
                    dst[i] -= src[i] * f
        j0 = j1
    return -1


@njit(cache=True)
def _numeric(
    n, indptr, indices, data, perm, iperm, sfirst, sup, Lpi, Ls, Lpx, wsize
):  # pragma: no cover
    """Left-looking supernodal Cholesky of ``P K P^T``: scatter, descendant updates in a
    structural order, :func:`_factor_block`. Returns ``(Lx, bad)`` (``bad``: pivot column or -1).
    """
    ns = sfirst.size - 1
    Lx = np.zeros(Lpx[ns], np.float64)
    head = np.full(ns, -1, np.int64)
    nxt = np.full(ns, -1, np.int64)
    lpos = np.zeros(ns, np.int64)
    rmap = np.full(n, -1, np.int64)
    W = np.empty(max(wsize, 1), np.float64)
    rel = np.empty(n, np.int64)
    for s in range(ns):
        k1 = sfirst[s]
        k2 = sfirst[s + 1]
        nscol = k2 - k1
        psi = Lpi[s]
        nsrow = Lpi[s + 1] - psi
        psx = Lpx[s]
        for r in range(nsrow):
            rmap[Ls[psi + r]] = r
        for j in range(k1, k2):
            pj = psx + (j - k1) * nsrow
            r = perm[j]
            for p in range(indptr[r], indptr[r + 1]):
                i = iperm[indices[p]]
                if i >= j:
                    Lx[pj + rmap[i]] = data[p]
        d = head[s]
        while d != -1:
            dnext = nxt[d]
            pdi = Lpi[d]
            ndrow = Lpi[d + 1] - pdi
            ndcol = sfirst[d + 1] - sfirst[d]
            pdx = Lpx[d]
            p1 = lpos[d]
            p2 = p1
            while p2 < ndrow and Ls[pdi + p2] < k2:
                p2 += 1
            nr1 = p2 - p1
            nr2 = ndrow - p1
            for q in range(nr1 * nr2):
                W[q] = 0.0
            _gemm_nt_sub(W, 0, nr2, Lx, pdx + p1, ndrow, Lx, pdx + p1, ndrow, nr2, nr1, ndcol, True)
            for ii in range(nr2):
                rel[ii] = rmap[Ls[pdi + p1 + ii]]
            for jj in range(nr1):
                pc = psx + (Ls[pdi + p1 + jj] - k1) * nsrow
                pw = jj * nr2
                for ii in range(jj, nr2):
                    Lx[pc + rel[ii]] += W[pw + ii]
            lpos[d] = p2
            if p2 < ndrow:
                t = sup[Ls[pdi + p2]]
                nxt[d] = head[t]
                head[t] = d
            d = dnext
        bad = _factor_block(Lx, psx, nsrow, nsrow, nscol)
        if bad >= 0:
            return Lx, k1 + bad
        if nsrow > nscol:
            lpos[s] = nscol
            t = sup[Ls[psi + nscol]]
            nxt[s] = head[t]
            head[t] = s
    return Lx, -1


@njit(cache=True)
def _solve_inplace(sfirst, Lpi, Ls, Lpx, Lx, X):  # pragma: no cover - jitted
    """``X <- (L L^T)^{-1} X`` for permuted right-hand sides (n, m): forward by supernodes,
    backward in reverse, sums in ascending index, each column independent of the others.
    """
    ns = sfirst.size - 1
    m = X.shape[1]
    for s in range(ns):
        k1 = sfirst[s]
        nscol = sfirst[s + 1] - k1
        psi = Lpi[s]
        nsrow = Lpi[s + 1] - psi
        psx = Lpx[s]
        for j in range(nscol):
            col = k1 + j
            pj = psx + j * nsrow
            piv = Lx[pj + j]
            for c in range(m):
                X[col, c] = X[col, c] / piv
            for i in range(j + 1, nsrow):
                row = Ls[psi + i]
                lij = Lx[pj + i]
                for c in range(m):
                    X[row, c] -= lij * X[col, c]
    for s in range(ns - 1, -1, -1):
        k1 = sfirst[s]
        nscol = sfirst[s + 1] - k1
        psi = Lpi[s]
        nsrow = Lpi[s + 1] - psi
        psx = Lpx[s]
        for j in range(nscol - 1, -1, -1):
            col = k1 + j
            pj = psx + j * nsrow
            for i in range(j + 1, nsrow):
                row = Ls[psi + i]
                lij = Lx[pj + i]
                for c in range(m):
                    X[col, c] -= lij * X[row, c]
            piv = Lx[pj + j]
            for c in range(m):
                X[col, c] = X[col, c] / piv


@njit(cache=True)
def _solve_gathered(sfirst, Lpi, Ls, Lpx, Lx, X):  # pragma: no cover - jitted
    """:func:`_solve_inplace` for a few right-hand sides with the same operations in the same
    order, on a gathered column-major buffer per supernode.
    """
    ns = sfirst.size - 1
    m = X.shape[1]
    big = 0
    for s in range(ns):
        big = max(big, Lpi[s + 1] - Lpi[s])
    T = np.empty(big * max(m, 1), np.float64)
    for s in range(ns):
        k1 = sfirst[s]
        nscol = sfirst[s + 1] - k1
        psi = Lpi[s]
        nsrow = Lpi[s + 1] - psi
        psx = Lpx[s]
        rows = Ls[psi : psi + nsrow]
        for i in range(nsrow):
            r = rows[i]
            for c in range(m):
                T[c * nsrow + i] = X[r, c]
        for j in range(nscol):
            pj = psx + j * nsrow
            piv = Lx[pj + j]
            lv = Lx[pj + j + 1 : pj + nsrow]
            for c in range(m):
                xj = T[c * nsrow + j] / piv
                T[c * nsrow + j] = xj
                tv = T[c * nsrow + j + 1 : (c + 1) * nsrow]
                for i in range(nsrow - j - 1):
                    tv[i] -= lv[i] * xj
        for i in range(nsrow):
            r = rows[i]
            for c in range(m):
                X[r, c] = T[c * nsrow + i]
    for s in range(ns - 1, -1, -1):
        k1 = sfirst[s]
        nscol = sfirst[s + 1] - k1
        psi = Lpi[s]
        nsrow = Lpi[s + 1] - psi
        psx = Lpx[s]
        rows = Ls[psi : psi + nsrow]
        for i in range(nsrow):
            r = rows[i]
            for c in range(m):
                T[c * nsrow + i] = X[r, c]
        for j in range(nscol - 1, -1, -1):
            pj = psx + j * nsrow
            lv = Lx[pj : pj + nsrow]
            piv = lv[j]
            c0 = 0
            while c0 < m:
                # four columns (fewer at the end: the last one repeated, computed twice alike)
                w = min(4, m - c0)
                e1 = c0 + min(1, w - 1)
                e2 = c0 + min(2, w - 1)
                e3 = c0 + min(3, w - 1)
                t0 = T[c0 * nsrow : (c0 + 1) * nsrow]
                t1 = T[e1 * nsrow : (e1 + 1) * nsrow]
                t2 = T[e2 * nsrow : (e2 + 1) * nsrow]
                t3 = T[e3 * nsrow : (e3 + 1) * nsrow]
                a0 = t0[j]
                a1 = t1[j]
                a2 = t2[j]
                a3 = t3[j]
                for i in range(j + 1, nsrow):
                    lij = lv[i]
                    a0 -= lij * t0[i]
                    a1 -= lij * t1[i]
                    a2 -= lij * t2[i]
                    a3 -= lij * t3[i]
                t0[j] = a0 / piv
                t1[j] = a1 / piv
                t2[j] = a2 / piv
                t3[j] = a3 / piv
                c0 += w
        for i in range(nscol):
            for c in range(m):
                X[k1 + i, c] = T[c * nsrow + i]


class SparseCholesky:
    """Supernodal Cholesky factorisation ``K = P^T L L^T P`` with a fixed operation order.

    ``K`` (n, n) is sparse, symmetric positive definite with a symmetric pattern; ``perm`` (n,)
    is a fill-reducing order (default :func:`fill_reducing_order`), refined by a postorder. The
    result of :meth:`solve` depends only on ``K`` and the right-hand sides, bit for bit.
    ``numpy.linalg.LinAlgError`` is raised when a pivot is not positive.
    """

    def __init__(self, K: sp.spmatrix, perm: np.ndarray | None = None) -> None:
        K = _canonical_csr(K)
        n = K.shape[0]
        if K.shape != (n, n):
            raise InvalidInputError(f"`K` must be square; got shape {K.shape}.")
        self.n = n
        if perm is None:
            perm = fill_reducing_order(K)
        perm = np.asarray(perm, dtype=np.int64)
        indptr, indices, data = K.indptr, K.indices, K.data.astype(np.float64, copy=False)
        iperm = np.empty(n, np.int64)
        iperm[perm] = np.arange(n)
        parent = _etree(n, indptr, indices, perm, iperm)
        post = _postorder(parent)
        # a postorder renumbers the elimination tree without changing it (or the fill)
        ipost = np.empty(n, np.int64)
        ipost[post] = np.arange(n)
        parent = parent[post]
        parent[parent >= 0] = ipost[parent[parent >= 0]]
        perm = perm[post]
        iperm[perm] = np.arange(n)
        cc = _colcounts(n, indptr, indices, perm, iperm, parent)
        sfirst = _supernodes(n, parent, cc)
        sup, Lpi, Ls = _super_rows(n, indptr, indices, perm, iperm, parent, sfirst)
        ncol = np.diff(sfirst)
        nrow = np.diff(Lpi)
        Lpx = np.zeros(sfirst.size, np.int64)
        np.cumsum(ncol * nrow, out=Lpx[1:])
        wsize = _update_workspace(sfirst, sup, Lpi, Ls)
        Lx, bad = _numeric(n, indptr, indices, data, perm, iperm, sfirst, sup, Lpi, Ls, Lpx, wsize)
        if bad >= 0:
            raise np.linalg.LinAlgError(
                f"the matrix is not positive definite (pivot {int(bad)} of the ordered matrix)."
            )
        self.perm = perm
        self.sfirst, self.Lpi, self.Ls, self.Lpx, self.Lx = sfirst, Lpi, Ls, Lpx, Lx
        self.nnz = int(Lpx[-1])
        self.n_supernodes = int(sfirst.size - 1)

    def solve(self, B: np.ndarray) -> np.ndarray:
        """``K^{-1} B`` for ``B`` of shape (n,) or (n, m); a new float64 array of ``B``'s shape."""
        B = np.asarray(B, dtype=np.float64)
        if B.shape[:1] != (self.n,) or B.ndim > 2:
            raise InvalidInputError(
                f"`B` must have shape ({self.n},) or ({self.n}, m); got {B.shape}."
            )
        vec = B.ndim == 1
        X = np.ascontiguousarray(B.reshape(self.n, -1)[self.perm])
        if X.shape[1] <= _FEW_RHS:
            _solve_gathered(self.sfirst, self.Lpi, self.Ls, self.Lpx, self.Lx, X)
        else:
            _solve_inplace(self.sfirst, self.Lpi, self.Ls, self.Lpx, self.Lx, X)
        out = np.empty_like(X)
        out[self.perm] = X
        return out[:, 0] if vec else out
