"""Approximate minimum degree order in integer arithmetic (Amestoy, Davis and Duff, 1996), the
same on every machine, for :mod:`._cholesky`.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from numba import njit


# ----------------------------------------------------------------------------- ordering
def fill_reducing_order(K: sp.spmatrix) -> np.ndarray:
    """Approximate minimum degree order ``perm`` (n,) int64 of the pattern of the symmetric
    ``K``: row / column ``perm[i]`` becomes ``i``.
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
    """Move the lists of ``owners`` to the front of ``iw``; returns the first free position."""
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
    r"""Approximate minimum degree order of a symmetric graph (compressed rows, diagonal skipped).

    Quotient-graph elimination: pivots become elements; each step eliminates a variable of least
    approximate external degree (ties: latest in its bucket), absorbs the elements it touches and
    bounds the degrees by ``min(old, |A_i| + sum_e |L_e \ L_me|) + |L_me| - |i|``, with mass
    elimination and hashed supervariables; rows with more than ``max(16, 10 sqrt(n))`` neighbours
    go last. ``elbow`` is spare room in ``iw``. Returns the elimination rank of every node.
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
