"""Full eigenbases of submesh Laplacians applied without forming them (spectral codec kernels).

When ``k`` covers a submesh, ``L = Q T Q^T`` (Householder), ``T = Z diag(w) Z^T`` (implicit QL,
rotations recorded) and ``U = Q Z P S`` (``P`` sorts ascending, ``S`` makes the first vertex's
entry non-negative); ``U^T x`` and ``U c`` apply the reflectors and rotations in ``O(n_i^2)``.
Every step is a loop of :mod:`._dense_fixed`; a thread pool runs the submeshes, each computed
the same way whatever the thread count. :func:`overlapped_submeshes` is
:mod:`spectrageo.spectral.partition`'s construction with its growth compiled.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .._threads import default_workers, thread_map
from ._dense_fixed import apply_q, apply_qt, ql_rotations, rotate, rotate_t, tridiagonalise

#: submeshes handed to a worker thread at a time
CHUNK = 16


@njit(nogil=True, cache=True)
def _dense_laplacian(indptr, indices, part, buf):
    """Dense binary Laplacian ``D - C`` of the subgraph induced by the sorted vertex set ``part``,
    in the first ``n^2`` entries of the scratch ``buf``."""
    n = part.size
    L = buf[: n * n].reshape(n, n)
    L[:, :] = 0.0
    for a in range(n):
        g = part[a]
        deg = 0.0
        for p in range(indptr[g], indptr[g + 1]):
            v = indices[p]
            b = np.searchsorted(part, v)
            if b < n and part[b] == v and b != a and L[a, b] == 0.0:
                L[a, b] = -1.0
                deg += 1.0
        L[a, a] = deg
    return L


@njit(nogil=True, cache=True)
def _workspace(offs, lo, hi):
    """Scratch for the submeshes ``lo..hi-1``: a Laplacian buffer and rotation arrays."""
    nmax = 1
    for i in range(lo, hi):
        nmax = max(nmax, offs[i + 1] - offs[i])
    cap = 2 * nmax * nmax + 16
    return np.empty(nmax * nmax), np.empty(cap, np.int32), np.empty(cap), np.empty(cap)


@njit(nogil=True, cache=True)
def _decompose(indptr, indices, part, ws):
    """Everything that defines ``U = Q Z P S`` for one submesh.

    ``ws`` is the scratch of :func:`_workspace`. Returns ``(A, tau, idx, cs, sn, M, order, sign,
    info)``: the reflectors of ``Q``, the ``M`` rotations of ``Z``, ``order`` the eigenvalue
    indices in ascending order (stable sort; column ``j`` of ``U`` is eigenvector ``order[j]``) and
    ``sign`` (+-1 per eigenvector) making the first row of ``U`` non-negative. ``info != 0`` when
    the QL iteration does not converge.
    """
    n = part.size
    buf, idx, cs, sn = ws
    A = _dense_laplacian(indptr, indices, part, buf)
    tau, d, e = tridiagonalise(A)
    # first row of U = first row of Z (Q leaves the first coordinate alone) = e_0^T Z, made
    # by the QL iteration as it records the rotations
    r = np.zeros(n)
    r[0] = 1.0
    idx, cs, sn, M, info = ql_rotations(d, e, idx, cs, sn, r)
    order = np.argsort(d, kind="mergesort")
    sign = np.ones(n)
    for j in range(n):
        if r[j] < 0.0:
            sign[j] = -1.0
    return A, tau, idx, cs, sn, M, order, sign, info


@njit(nogil=True, cache=True)
def _transform_range(indptr, indices, flat, offs, lo, hi, src, out, status, synthesise):
    """``out[rows of submesh i] = U_i^T src[part_i]`` (analysis) or ``U_i src[rows of submesh
    i]`` (``synthesise``) for the submeshes ``lo..hi-1``."""
    d = src.shape[1]
    ws = _workspace(offs, lo, hi)
    for i in range(lo, hi):
        part = flat[offs[i] : offs[i + 1]]
        A, tau, idx, cs, sn, M, order, sign, info = _decompose(indptr, indices, part, ws)
        ws = (ws[0], idx, cs, sn)
        status[i] = info
        if info != 0:
            continue
        o = offs[i]
        Y = np.empty((part.size, d))
        if synthesise:
            for j in range(part.size):
                q = order[j]
                for c in range(d):
                    Y[q, c] = sign[q] * src[o + j, c]
            rotate(idx, cs, sn, M, Y)
            apply_q(A, tau, Y)
            out[o : offs[i + 1]] = Y
        else:
            _analyse_one(A, tau, idx, cs, sn, M, order, sign, part, src, Y, out, o)


@njit(nogil=True, cache=True)
def _analyse_one(A, tau, idx, cs, sn, M, order, sign, part, src, Y, out, o):
    """``out[o + j] = (U^T src[part])[j]`` for one decomposed submesh (``Y``: (n_i, d) scratch)."""
    d = src.shape[1]
    for a in range(part.size):
        for c in range(d):
            Y[a, c] = src[part[a], c]
    apply_qt(A, tau, Y)
    rotate_t(idx, cs, sn, M, Y)
    for j in range(part.size):
        q = order[j]
        for c in range(d):
            out[o + j, c] = sign[q] * Y[q, c]


@njit(nogil=True, cache=True)
def _basis_one(A, tau, idx, cs, sn, M, order, sign, n):
    """The explicit basis ``U = Q (Z P S)`` (n, n) of one decomposed submesh."""
    W = np.zeros((n, n))
    for j in range(n):
        W[order[j], j] = sign[order[j]]
    rotate(idx, cs, sn, M, W)
    apply_q(A, tau, W)
    return W


@njit(nogil=True, cache=True)
def _analyse_range(indptr, indices, flat, offs, lo, hi, X, out, status):
    """``out[rows of submesh i] = U_i^T X[part_i]`` for the submeshes ``lo..hi-1``."""
    _transform_range(indptr, indices, flat, offs, lo, hi, X, out, status, False)


@njit(nogil=True, cache=True)
def _synthesise_range(indptr, indices, flat, offs, lo, hi, coef, out, status):
    """``out[rows of submesh i] = U_i coef[rows of submesh i]`` for the submeshes ``lo..hi-1``."""
    _transform_range(indptr, indices, flat, offs, lo, hi, coef, out, status, True)


@njit(nogil=True, cache=True)
def _bases_range(indptr, indices, flat, offs, lo, hi, X, out, boffs, bout, analyse, status):
    """The explicit bases ``U_i = Q (Z P S)`` of the submeshes ``lo..hi-1``, row-major into
    ``bout[boffs[i]:boffs[i + 1]]``, and with ``analyse`` :func:`_analyse_range` into ``out``."""
    ws = _workspace(offs, lo, hi)
    for i in range(lo, hi):
        part = flat[offs[i] : offs[i + 1]]
        n = part.size
        A, tau, idx, cs, sn, M, order, sign, info = _decompose(indptr, indices, part, ws)
        ws = (ws[0], idx, cs, sn)
        status[i] = info
        if info != 0:
            continue
        if analyse:
            Y = np.empty((n, X.shape[1]))
            _analyse_one(A, tau, idx, cs, sn, M, order, sign, part, X, Y, out, offs[i])
        W = _basis_one(A, tau, idx, cs, sn, M, order, sign, n)
        bout[boffs[i] : boffs[i + 1]] = W.ravel()


class FullBases:
    """The full Laplacian eigenbases ``U_i`` (``n_i x n_i``) of a set of submeshes, applied lazily.

    Parameters
    ----------
    C : csr_matrix (n, n), adjacency of the mesh (only its sparsity pattern is used)
    parts : list of sorted (n_i,) int arrays
    workers : int, optional
        Threads (default :func:`default_workers`); the result does not depend on it.
    """

    def __init__(self, C, parts, workers: int | None = None) -> None:
        self.indptr = np.ascontiguousarray(C.indptr, dtype=np.int64)
        self.indices = np.ascontiguousarray(C.indices, dtype=np.int64)
        self.parts = parts
        self.sizes = np.array([p.size for p in parts], dtype=np.int64)
        self.offs = np.zeros(len(parts) + 1, dtype=np.int64)
        np.cumsum(self.sizes, out=self.offs[1:])
        self.flat = (
            np.ascontiguousarray(np.concatenate(parts), dtype=np.int64)
            if parts
            else np.zeros(0, np.int64)
        )
        self.workers = default_workers() if workers is None else max(1, int(workers))

    def _run(self, kernel, *args) -> None:
        m = len(self.parts)
        status = np.zeros(m, dtype=np.int64)
        ranges = [(a, min(a + CHUNK, m)) for a in range(0, m, CHUNK)]

        def job(r):
            kernel(self.indptr, self.indices, self.flat, self.offs, r[0], r[1], *args, status)

        thread_map(job, ranges, self.workers)
        if status.any():
            i = int(np.flatnonzero(status)[0])
            raise np.linalg.LinAlgError(
                f"the eigendecomposition of the Laplacian of submesh {i} failed (info={status[i]})."
            )

    def analyse(self, X: np.ndarray) -> list[np.ndarray]:
        """Coefficients ``U_i^T X[parts[i]]`` of every submesh ((n_i, d) each)."""
        X = np.ascontiguousarray(X, dtype=np.float64)
        out = np.empty((self.flat.size, X.shape[1]))
        self._run(_analyse_range, X, out)
        return np.split(out, self.offs[1:-1])

    def synthesise(self, coefs) -> list[np.ndarray]:
        """``U_i c_i`` of every submesh; ``coefs[i]`` has ``n_i`` rows (missing ones as zeros)."""
        d = coefs[0].shape[1] if coefs else 3
        flat = np.zeros((self.flat.size, d))
        for i, c in enumerate(coefs):
            flat[self.offs[i] : self.offs[i] + c.shape[0]] = c
        out = np.empty_like(flat)
        self._run(_synthesise_range, flat, out)
        return np.split(out, self.offs[1:-1])

    def _basis_offsets(self) -> np.ndarray:
        boffs = np.zeros(len(self.parts) + 1, dtype=np.int64)
        np.cumsum(self.sizes**2, out=boffs[1:])
        return boffs

    def _split_bases(self, out: np.ndarray, boffs: np.ndarray) -> list[np.ndarray]:
        return [out[a:b].reshape(s, s) for a, b, s in zip(boffs[:-1], boffs[1:], self.sizes)]

    def explicit(self) -> list[np.ndarray]:
        """The bases ``U_i`` as dense (n_i, n_i) arrays, columns in ascending eigenvalue order."""
        boffs = self._basis_offsets()
        bout = np.empty(int(boffs[-1]))
        none = np.zeros((0, 3))
        self._run(_bases_range, none, none, boffs, bout, False)
        return self._split_bases(bout, boffs)

    def analyse_explicit(self, X: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """``(analyse(X), explicit())`` from one decomposition per submesh (the same values)."""
        X = np.ascontiguousarray(X, dtype=np.float64)
        out = np.empty((self.flat.size, X.shape[1]))
        boffs = self._basis_offsets()
        bout = np.empty(int(boffs[-1]))
        self._run(_bases_range, X, out, boffs, bout, True)
        return np.split(out, self.offs[1:-1]), self._split_bases(bout, boffs)


# ----------------------------------------------------------------------------- submeshes
@njit(cache=True)
def _grow_all(indptr, indices, cores_flat, cores_offs, size, n):
    """Compiled equivalent of the breadth-first growth of
    :func:`spectrageo.spectral.partition.overlapped_submeshes` for every core (same rings, same
    truncation order, same restarts), with the in-submesh degrees.

    Returns ``(parts, degrees)``, both (n_cores, size) (sorted vertex indices per row).
    """
    m = cores_offs.size - 1
    parts = np.empty((m, size), np.int64)
    degs = np.empty((m, size), np.int64)
    marker = np.zeros(n, np.bool_)
    inring = np.zeros(n, np.bool_)
    buf = np.empty(size, np.int64)
    ring = np.empty(n, np.int64)
    for k in range(m):
        core = cores_flat[cores_offs[k] : cores_offs[k + 1]]
        cnt = core.size
        for a in range(cnt):
            buf[a] = core[a]
            marker[core[a]] = True
        f0 = 0
        f1 = cnt
        while cnt < size:
            nr = 0
            for a in range(f0, f1):
                g = buf[a]
                for p in range(indptr[g], indptr[g + 1]):
                    v = indices[p]
                    if not marker[v] and not inring[v]:
                        inring[v] = True
                        ring[nr] = v
                        nr += 1
            for a in range(nr):
                inring[ring[a]] = False
            if nr == 0:
                # component exhausted: the unvisited vertex closest in index to the core
                best = -1
                bd = n + 1
                for v in range(n):
                    if not marker[v]:
                        dv = abs(v - core[0])
                        if dv < bd:
                            bd = dv
                            best = v
                ring[0] = best
                nr = 1
            r = np.sort(ring[:nr])
            need = size - cnt
            if nr > need:
                # most neighbours already inside first, then lower index
                key = np.empty(nr, np.int64)
                for a in range(nr):
                    v = r[a]
                    inside = 0
                    for p in range(indptr[v], indptr[v + 1]):
                        if marker[indices[p]]:
                            inside += 1
                    key[a] = -inside * (n + 1) + v
                r = r[np.argsort(key, kind="mergesort")[:need]]
            for a in range(r.size):
                marker[r[a]] = True
                buf[cnt + a] = r[a]
            f0 = cnt
            f1 = cnt + r.size
            cnt += r.size
        part = np.sort(buf)
        parts[k] = part
        for a in range(size):
            marker[part[a]] = True
        for a in range(size):
            g = part[a]
            dg = 0
            for p in range(indptr[g], indptr[g + 1]):
                if marker[indices[p]]:
                    dg += 1
            degs[k, a] = dg
        for a in range(size):
            marker[part[a]] = False
    return parts, degs


def overlapped_submeshes(C, *, submesh_size: int, overlap: float, rng):
    """:func:`spectrageo.spectral.partition.overlapped_submeshes` (same METIS parts, same grown
    submeshes and degrees) with the growth compiled; ``C`` as from
    :func:`spectrageo.graph.adjacency_matrix`."""
    from .._validation import as_rng
    from ..spectral import partition as P

    C = P.as_adjacency(C)
    n = C.shape[0]
    size = int(submesh_size)
    if n <= size:
        return P.overlapped_submeshes(C, submesh_size=size, overlap=overlap, rng=rng)
    pattern = C.copy()
    pattern.data[:] = 1.0
    cores = P.metis_cores(pattern, size, overlap, int(as_rng(rng).integers(0, 2**31 - 1)))
    offs = np.zeros(len(cores) + 1, dtype=np.int64)
    np.cumsum([c.size for c in cores], out=offs[1:])
    parts, degs = _grow_all(
        pattern.indptr.astype(np.int64),
        pattern.indices.astype(np.int64),
        np.concatenate(cores).astype(np.int64),
        offs,
        size,
        n,
    )
    return P.Submeshes(list(parts), cores, n, list(degs))
