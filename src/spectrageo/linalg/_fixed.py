"""Linear algebra with a fixed order of floating-point operations (bit-identical decoders).

The decoders of :mod:`spectrageo.compress` must turn the same bytes into the same coordinates
on every machine. BLAS and LAPACK cannot promise that: OpenBLAS picks its kernels by CPU
(``OPENBLAS_CORETYPE``), splits work by thread count, and its kernels sum in an order that
follows the vector width. The kernels here are numba loops whose order of additions is a
function of the input's structure alone:

* no call into BLAS or LAPACK (``np.dot`` and ``@`` inside numba call BLAS, so they are
  not used);
* every sum runs in one written order; a loop that LLVM vectorises runs over independent
  outputs (an ``axpy``), never over the terms of one sum, so a wider or narrower vector
  unit computes the same values;
* compiled without ``fastmath``: LLVM neither reassociates sums nor contracts a multiply
  and an add into a fused multiply-add, so a CPU with FMA rounds like one without;
* only ``+ - * /`` and ``sqrt``, all correctly rounded in IEEE 754.

Contents:

* :class:`SparseCholesky`: ``K = P^T L L^T P`` of a sparse symmetric positive definite ``K``
  with an approximate minimum degree order (integer arithmetic only) made into a
  postordered elimination tree, relaxed supernodes, a left-looking supernodal numeric
  factorisation with blocked dense kernels, and forward / backward solves for many
  right-hand sides. Used for the normal equations of the anchored Laplacian systems
  ``(L^T L + I_a^T I_a) v = L^T delta + I_a^T v_a`` (Eq. 5.51, 5.54).
* :func:`matmul`: dense ``A @ B`` summed in index order.
* :func:`orthonormal_columns`: Householder QR, the ``Q`` factor with a positive ``R`` diagonal.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from numba import njit

from .._errors import InvalidInputError

#: columns of a supernode factorised as one panel by the blocked dense Cholesky
_PANEL = 64
#: rows of the output held while a dense update streams its inner dimension
_ROW_BLOCK = 256
#: right-hand sides up to which the solves gather each supernode's rows into a buffer
_FEW_RHS = 8


# ----------------------------------------------------------------------------- ordering
def fill_reducing_order(K: sp.spmatrix) -> np.ndarray:
    """Approximate minimum degree order of the graph of the symmetric ``K``
    (:func:`_min_degree`).

    Integer arithmetic on the pattern of ``K`` only, so the order is the same on every
    machine. Returns ``perm`` (n,) int64: row / column ``perm[i]`` of ``K`` becomes row /
    column ``i``.
    """
    K = _canonical_csr(K)
    n = K.shape[0]
    if n <= 2:
        return np.arange(n, dtype=np.int64)
    key = _min_degree(n, K.indptr, K.indices, K.nnz // 5 + 2 * n + 64)
    return np.argsort(key, kind="stable").astype(np.int64)


def _canonical_csr(K) -> sp.csr_matrix:
    """``K`` as CSR with sorted, summed indices (a copy only where ``K`` is not one)."""
    K = sp.csr_matrix(K)
    if not K.has_canonical_format:
        K = K.copy()
        K.sum_duplicates()
    return K


@njit(cache=True)
def _compact_lists(iw, pe, ln, owners):  # pragma: no cover - jitted
    """Move the lists of ``owners`` to the front of ``iw`` in their order of position; returns
    the first free position."""
    order = np.argsort(pe[owners], kind="mergesort")
    dst = 0
    for t in range(order.size):
        x = owners[order[t]]
        src = pe[x]
        for q in range(ln[x]):
            iw[dst + q] = iw[src + q]
        pe[x] = dst
        dst += ln[x]
    return dst


@njit(cache=True)
def _min_degree(n, xadj, adj, elbow):  # pragma: no cover - jitted
    """Approximate minimum degree order of a symmetric graph (compressed rows; entries on the
    diagonal are skipped).

    Quotient-graph elimination: the eliminated pivots become *elements* (cliques stored as
    their variable lists), the remaining *variables* keep their lists of adjacent elements
    and variables in one workspace ``iw``. Each step takes a variable of least approximate
    external degree (ties: the one most recently put in its degree bucket), forms its
    element from the variables it reaches (absorbing the elements it touches), and updates
    the degrees of those variables with the bound of Amestoy, Davis and Duff (1996):
    ``min(old degree, |A_i| + sum_e |L_e \\ L_me|) + |L_me| - |i|``. Elements contained in the
    new one are absorbed, variables left with no other neighbour are eliminated with the
    pivot (mass elimination), and variables with identical lists are merged into
    supervariables (found by a hash of their lists). Rows with more than ``10 sqrt(n)``
    (at least 16) neighbours are left out and ordered last. Integer arithmetic only.

    ``elbow`` is the room in ``iw`` beyond the adjacency for new elements; when it runs out the
    lists are compacted, and ``iw`` grows if that is not enough (neither changes the order).
    Returns the rank of every node in the elimination order (a permutation's inverse).
    """
    iwlen = xadj[n] + elbow
    iw = np.empty(iwlen, np.int64)
    pe = np.empty(n, np.int64)
    ln = np.empty(n, np.int64)
    q = 0
    for i in range(n):
        pe[i] = q
        for p in range(xadj[i], xadj[i + 1]):
            j = adj[p]
            if j != i:
                iw[q] = j
                q += 1
        ln[i] = q - pe[i]
    nnz = q
    elen = np.zeros(n, np.int64)
    nv = np.ones(n, np.int64)
    degree = ln.copy()
    status = np.zeros(n, np.int8)  # 0 variable, 1 element, 2 gone (absorbed or eliminated)
    into = np.full(n, -1, np.int64)  # supervariable a merged variable joined
    rank = np.full(n, -1, np.int64)
    w = np.zeros(n, np.int64)
    mark = np.zeros(n, np.int64)
    tag = 0
    wflg = 2
    head = np.full(n + 1, -1, np.int64)
    nxt = np.full(n, -1, np.int64)
    prv = np.full(n, -1, np.int64)
    hhead = np.full(n, -1, np.int64)
    hnext = np.full(n, -1, np.int64)
    hbucket = np.zeros(n, np.int64)
    dense = max(16, int(10.0 * math.sqrt(n)))
    n_live = 0
    for i in range(n - 1, -1, -1):
        if degree[i] > dense and n > 16:
            status[i] = 2
            nv[i] = 0
            continue
        n_live += 1
        d = degree[i]
        nxt[i] = head[d]
        if head[d] != -1:
            prv[head[d]] = i
        head[d] = i
    r = 0
    nel = 0
    mindeg = 0
    lemax = 0
    pfree = nnz
    while nel < n_live:
        while head[mindeg] == -1:
            mindeg += 1
        me = head[mindeg]
        head[mindeg] = nxt[me]
        if nxt[me] != -1:
            prv[nxt[me]] = -1
        elenme = elen[me]
        nvpiv = nv[me]
        nel += nvpiv
        rank[me] = r
        r += 1
        nv[me] = -nvpiv
        degme = 0
        # ---- the new element L_me
        if elenme == 0:
            pme1 = pe[me]
            pme2 = pme1 - 1
            for p in range(pe[me], pe[me] + ln[me]):
                j = iw[p]
                nvj = nv[j]
                if nvj <= 0:
                    continue
                degme += nvj
                nv[j] = -nvj
                pme2 += 1
                iw[pme2] = j
                _unlink(j, degree, head, nxt, prv)
        else:
            bound = ln[me] - elenme
            for p in range(pe[me], pe[me] + elenme):
                e = iw[p]
                if status[e] == 1:
                    bound += ln[e]
            if pfree + bound > iwlen:
                cnt = 0
                for x in range(n):
                    if (status[x] == 0 and nv[x] != 0) or (status[x] == 1 and ln[x] > 0):
                        cnt += 1
                owners = np.empty(cnt, np.int64)
                cnt = 0
                for x in range(n):
                    if (status[x] == 0 and nv[x] != 0) or (status[x] == 1 and ln[x] > 0):
                        owners[cnt] = x
                        cnt += 1
                pfree = _compact_lists(iw, pe, ln, owners)
                if pfree + bound > iwlen:
                    iwlen = 2 * iwlen + bound
                    bigger = np.empty(iwlen, np.int64)
                    bigger[:pfree] = iw[:pfree]
                    iw = bigger
            pme1 = pfree
            pme2 = pfree - 1
            for p in range(pe[me], pe[me] + ln[me]):
                x = iw[p]
                if p < pe[me] + elenme:
                    if status[x] != 1:
                        continue
                    q0 = pe[x]
                    q1 = q0 + ln[x]
                    status[x] = 2  # absorbed into me
                else:
                    q0 = p
                    q1 = p + 1
                for q in range(q0, q1):
                    j = iw[q]
                    nvj = nv[j]
                    if nvj <= 0:
                        continue
                    degme += nvj
                    nv[j] = -nvj
                    pme2 += 1
                    iw[pme2] = j
                    _unlink(j, degree, head, nxt, prv)
            pfree = pme2 + 1
        status[me] = 1
        pe[me] = pme1
        ln[me] = pme2 - pme1 + 1
        elen[me] = 0
        # ---- |L_e \ L_me| for the elements next to L_me, as w[e] - wflg
        if wflg > (1 << 60):
            for x in range(n):
                if w[x] != 0:
                    w[x] = 1
            wflg = 2
        for p in range(pme1, pme2 + 1):
            i = iw[p]
            nvi = -nv[i]
            for q in range(pe[i], pe[i] + elen[i]):
                e = iw[q]
                if status[e] != 1:
                    continue
                we = w[e]
                if we >= wflg:
                    we -= nvi
                else:
                    we = degree[e] + wflg - nvi
                w[e] = we
        # ---- degree bounds; absorb elements inside L_me; mass elimination
        for p in range(pme1, pme2 + 1):
            i = iw[p]
            p1 = pe[i]
            p2 = p1 + elen[i]
            pn = p1
            d = 0
            h = 0
            for q in range(p1, p2):
                e = iw[q]
                if status[e] != 1:
                    continue
                dext = w[e] - wflg
                if dext > 0:
                    d += dext
                    iw[pn] = e
                    pn += 1
                    h += e
                else:
                    status[e] = 2  # aggressive absorption into me
            ne = pn - p1
            p3 = pn
            for q in range(p2, p1 + ln[i]):
                j = iw[q]
                nvj = nv[j]
                if nvj <= 0:
                    continue
                d += nvj
                iw[pn] = j
                pn += 1
                h += j
            if d == 0:
                nvi = -nv[i]
                degme -= nvi
                nvpiv += nvi
                nel += nvi
                nv[i] = 0
                status[i] = 2
                rank[i] = r
                r += 1
            else:
                if d < degree[i]:
                    degree[i] = d
                iw[pn] = iw[p3]
                iw[p3] = iw[p1]
                iw[p1] = me
                elen[i] = ne + 1
                ln[i] = pn - p1 + 1
                hb = h % n
                hnext[i] = hhead[hb]
                hhead[hb] = i
                hbucket[i] = hb
        degree[me] = degme
        if degme > lemax:
            lemax = degme
        wflg += lemax + 1
        # ---- supervariables: variables of L_me with identical lists
        for p in range(pme1, pme2 + 1):
            i = iw[p]
            if nv[i] >= 0:
                continue
            hb = hbucket[i]
            a = hhead[hb]
            if a == -1:
                continue
            hhead[hb] = -1
            while a != -1:
                if nv[a] >= 0:  # merged already or eliminated
                    a = hnext[a]
                    continue
                tag += 1
                for q in range(pe[a], pe[a] + ln[a]):
                    mark[iw[q]] = tag
                prev_b = a
                b = hnext[a]
                while b != -1:
                    same = nv[b] < 0 and ln[b] == ln[a] and elen[b] == elen[a]
                    if same:
                        for q in range(pe[b], pe[b] + ln[b]):
                            if mark[iw[q]] != tag:
                                same = False
                                break
                    if same:
                        nv[a] += nv[b]
                        nv[b] = 0
                        status[b] = 2
                        into[b] = a
                        hnext[prev_b] = hnext[b]
                    else:
                        prev_b = b
                    b = hnext[b]
                a = hnext[a]
        # ---- final degrees, back into the degree lists; L_me compacted
        pn = pme1
        live = n_live - nel
        for p in range(pme1, pme2 + 1):
            i = iw[p]
            nvi = -nv[i]
            if nvi <= 0:
                continue
            nv[i] = nvi
            d = degree[i] + degme - nvi
            if d > live - nvi:
                d = live - nvi
            degree[i] = d
            nxt[i] = head[d]
            prv[i] = -1
            if head[d] != -1:
                prv[head[d]] = i
            head[d] = i
            if d < mindeg:
                mindeg = d
            iw[pn] = i
            pn += 1
        nv[me] = nvpiv
        ln[me] = pn - pme1
        if elenme == 0:
            pass  # L_me was built in place; nothing to free
    # dense rows last, then merged variables take the rank of their supervariable
    for i in range(n):
        if rank[i] == -1 and into[i] == -1:
            rank[i] = r
            r += 1
    key = np.empty(n, np.int64)
    for i in range(n):
        x = i
        while rank[x] == -1:
            x = into[x]
        key[i] = rank[x]
    return key


@njit(cache=True, inline="always")
def _unlink(j, degree, head, nxt, prv):  # pragma: no cover - jitted
    """Remove ``j`` from its degree bucket."""
    a = prv[j]
    b = nxt[j]
    if b != -1:
        prv[b] = a
    if a != -1:
        nxt[a] = b
    else:
        head[degree[j]] = b


# ----------------------------------------------------------------------------- symbolic
@njit(cache=True)
def _etree(n, indptr, indices, perm, iperm):  # pragma: no cover - jitted
    """Elimination tree of ``P K P^T`` (Liu's algorithm with path compression) from the
    compressed rows of the symmetric ``K`` and the order ``perm`` (``iperm`` its inverse):
    row ``k`` of the permuted matrix is row ``perm[k]`` of ``K``, its column indices mapped by
    ``iperm``. ``parent[j] = -1`` at roots."""
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
    """Depth-first postorder of a forest, children in increasing order; ``post[k]`` is the
    node placed at position ``k``."""
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
    """Entries of every column of ``L`` (diagonal included), by walking the row subtrees
    (the permuted rows as in :func:`_etree`)."""
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
    """Relaxed supernodes of a postordered elimination tree; returns the first column of
    every supernode (and ``n`` at the end).

    Fundamental supernodes first (column ``j + 1`` joins ``j`` when it is ``j``'s parent and
    ``cc[j] == cc[j + 1] + 1``); then, from the last to the first, a supernode whose parent
    starts right after it is merged into the parent when the merged block has at most 4
    columns, or at most 16 columns and 50 % explicit zeros, or at most 48 columns and 10 %,
    or any size and 5 % (dense blocks run faster than many small ones).
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
    """Row pattern of every supernode (its own columns first, then the rows below, ascending):
    row ``k`` belongs to every supernode met on the paths of its row subtree."""
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
    """``C[i, j] -= sum_k A[i, k] B[j, k]`` for ``j < n`` and ``i < m`` (with ``i_lo``: only
    ``i >= j0`` in the group of four columns that starts at ``j0``, i.e. the lower trapezoid
    and a few entries above the diagonal that the callers never read).

    Column-major blocks in flat arrays: ``C[i, j]`` is ``C[c0 + i + j * ldc]``, likewise ``A``
    and ``B``. Every entry is updated as ``((C - A[i,0] B[j,0]) - A[i,1] B[j,1]) - ...``, the
    products subtracted one at a time in the order ``k = 0, 1, ..., kk - 1``, whatever the
    blocking: rows in blocks of :data:`_ROW_BLOCK` (so that the four output columns stay in
    the L1 cache), four columns and four ``k`` per pass. The innermost loop runs over rows:
    independent outputs, which LLVM vectorises without changing any sum.
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
    """Four columns of :func:`_gemm_nt_sub` over ``m`` rows (views, so that the row loop has
    a non-negative index and vectorises)."""
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
    """Cholesky of the leading ``ncol x ncol`` block of the column-major ``nrow x ncol`` block
    at ``X[x0]`` (leading dimension ``ld``), with the rows below divided by its transpose:
    ``[L11; L21]`` from ``[A11; A21]``. Panels of :data:`_PANEL` columns: each is first
    updated by all the columns before it (left-looking, :func:`_gemm_nt_sub`), then
    factorised column by column. Returns the column (relative) of a non-positive pivot,
    or -1."""
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
    """Left-looking supernodal Cholesky of ``P K P^T`` (``K`` in compressed rows, symmetric;
    the lower half of permuted column ``j`` is read from row ``perm[j]`` of ``K``).

    For every supernode in order: its columns of ``A`` are scattered into its dense block,
    every descendant that has rows in its columns subtracts its update ``L_d L_d[cols]^T``
    (descendants taken from linked lists, in an order fixed by the structure), and the block
    is factorised by :func:`_factor_block`. Returns ``(Lx, bad)``; ``bad`` is the column of a
    non-positive pivot, or -1.
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
    """``X <- (L L^T)^{-1} X`` for the permuted right-hand sides ``X`` (n, m), C order:
    forward substitution by supernodes in order, then backward in reverse order. Forward:
    ``x_j = b_j / L[j, j]``, then every row ``i`` below receives ``- L[i, j] x_j``, for the
    columns ``j`` in ascending order; backward: ``x_j = (b_j - sum_i L[i, j] x_i) / L[j, j]``
    with the sum in ascending ``i``, for ``j`` descending. Every right-hand side is treated
    alone (its result does not depend on the others); the loops over the ``m`` columns are
    the innermost ones."""
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
    """:func:`_solve_inplace` for a few right-hand sides, with the same operations in the
    same order (hence the same bits): each supernode gathers the rows of ``X`` it touches
    into a column-major buffer, works on it and scatters the result back, so that the
    forward loops over ``i`` run on contiguous memory (and vectorise) and the backward sums
    run four right-hand sides side by side."""
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

    Parameters
    ----------
    K : sparse matrix (n, n)
        Symmetric positive definite, with a symmetric pattern (the ordering reads the whole
        pattern, the factorisation the lower half of the permuted matrix).
    perm : ndarray (n,), optional
        Fill-reducing order (``perm[i]``: the row of ``K`` placed at ``i``); by default
        :func:`fill_reducing_order`. It is refined by a postorder of the elimination tree.

    Raises
    ------
    numpy.linalg.LinAlgError
        When a pivot is not positive (``K`` is not positive definite).

    Notes
    -----
    The result of :meth:`solve` depends on the values and pattern of ``K`` and on the right-hand
    sides only: the same inputs give the same bits on every machine, thread count and CPU
    (module notes). ``nnz`` is the number of stored factor entries (explicit zeros of the
    relaxed supernodes and the upper halves of their diagonal blocks included).
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


# ----------------------------------------------------------------------------- dense helpers
@njit(cache=True)
def _matmul_kernel(A, B, C):  # pragma: no cover - jitted
    """``C = A @ B`` (C-contiguous arrays): ``C[i, j] = ((A[i,0] B[0,j] + A[i,1] B[1,j]) + ...)``
    summed with ``k`` ascending, four ``k`` per pass over a row of ``C``; the innermost loop
    runs over ``j`` (independent outputs)."""
    m, kk = A.shape
    n = B.shape[1]
    for i in range(m):
        ci = C[i]
        for j in range(n):
            ci[j] = 0.0
        k = 0
        while k + 4 <= kk:
            a0 = A[i, k]
            a1 = A[i, k + 1]
            a2 = A[i, k + 2]
            a3 = A[i, k + 3]
            b0 = B[k]
            b1 = B[k + 1]
            b2 = B[k + 2]
            b3 = B[k + 3]
            for j in range(n):
                ci[j] = ci[j] + a0 * b0[j] + a1 * b1[j] + a2 * b2[j] + a3 * b3[j]
            k += 4
        while k < kk:
            a0 = A[i, k]
            b0 = B[k]
            for j in range(n):
                ci[j] += a0 * b0[j]
            k += 1


def matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Dense ``A @ B`` (float64) with every entry summed in index order, without BLAS.

    ``A`` (m, k), ``B`` (k, n); returns a new C-contiguous (m, n) array. The result does not
    depend on the memory layout of the inputs.
    """
    A = np.ascontiguousarray(A, dtype=np.float64)
    B = np.ascontiguousarray(B, dtype=np.float64)
    if A.ndim != 2 or B.ndim != 2 or A.shape[1] != B.shape[0]:
        raise InvalidInputError(f"`A` and `B` do not chain: shapes {A.shape} and {B.shape}.")
    C = np.empty((A.shape[0], B.shape[1]))
    _matmul_kernel(A, B, C)
    return C


@njit(cache=True)
def _householder_q(A):  # pragma: no cover - jitted
    """Householder QR of ``A`` (m, k), k <= m, in place; returns ``Q`` (m, k) with the signs
    that make the diagonal of ``R`` non-negative. Sums in index order."""
    m, k = A.shape
    V = np.zeros((m, k))
    tau = np.zeros(k)
    sgn = np.ones(k)
    for j in range(k):
        s = 0.0
        for i in range(j, m):
            s += A[i, j] * A[i, j]
        nrm = math.sqrt(s)
        alpha = A[j, j]
        if nrm == 0.0:
            V[j, j] = 1.0
            continue
        beta = -math.copysign(nrm, alpha)
        den = alpha - beta
        V[j, j] = 1.0
        for i in range(j + 1, m):
            V[i, j] = A[i, j] / den
        tau[j] = (beta - alpha) / beta
        if beta < 0.0:
            sgn[j] = -1.0
        for c in range(j + 1, k):
            w = 0.0
            for i in range(j, m):
                w += V[i, j] * A[i, c]
            w = tau[j] * w
            for i in range(j, m):
                A[i, c] -= w * V[i, j]
    Q = np.zeros((m, k))
    for j in range(k):
        Q[j, j] = 1.0
    for j in range(k - 1, -1, -1):
        for c in range(j, k):
            w = 0.0
            for i in range(j, m):
                w += V[i, j] * Q[i, c]
            w = tau[j] * w
            for i in range(j, m):
                Q[i, c] -= w * V[i, j]
    for i in range(m):
        for j in range(k):
            Q[i, j] = Q[i, j] * sgn[j]
    return Q


def orthonormal_columns(A: np.ndarray) -> np.ndarray:
    """``Q`` of the QR factorisation ``A = Q R`` (Householder) with ``R``'s diagonal made
    non-negative, for ``A`` (m, k) with ``k <= m``; a zero column keeps a unit vector. Every
    sum runs in index order (no LAPACK), so the result is the same on every machine."""
    A = np.array(A, dtype=np.float64, order="C", copy=True)
    if A.ndim != 2 or A.shape[1] > A.shape[0]:
        raise InvalidInputError(f"`A` must have shape (m, k) with k <= m; got {A.shape}.")
    if A.shape[1] == 0:
        return A
    return _householder_q(A)
