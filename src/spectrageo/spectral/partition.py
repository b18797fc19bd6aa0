"""Overlapped, equal-sized submeshes (Sections 5.1.1, 5.2.1) and their reassembly (Algorithm 8)."""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._errors import InvalidInputError
from .._validation import as_rng, check_choice, check_positive

__all__ = [
    "Submeshes",
    "as_adjacency",
    "induced_subgraph",
    "overlapped_submeshes",
    "reassemble",
    "submesh_laplacian",
]


def as_adjacency(C, name: str = "C", *, allow_negative: bool = False) -> sp.csr_matrix:
    """Symmetric sparse adjacency as CSR float64 without self-loops (validated)."""
    if not sp.issparse(C):
        raise InvalidInputError(
            f"`{name}` must be a scipy.sparse adjacency matrix; got {type(C).__name__}."
        )
    if C.ndim != 2 or C.shape[0] != C.shape[1]:
        raise InvalidInputError(f"`{name}` must be square; got shape {C.shape}.")
    if C.shape[0] == 0:
        raise InvalidInputError(f"`{name}` is empty; at least one vertex is required.")
    C = sp.csr_matrix(C, dtype=np.float64)
    if C.nnz and not np.isfinite(C.data).all():
        raise InvalidInputError(f"`{name}` contains NaN or inf weights.")
    if C.nnz and not allow_negative and C.data.min() < 0:
        raise InvalidInputError(f"`{name}` must have non-negative weights; got {C.data.min()!r}.")
    if C.diagonal().any():
        C = C.tolil()
        C.setdiag(0.0)
        C = C.tocsr()
    C.eliminate_zeros()
    C.sort_indices()
    asym = abs(C - C.T)
    if asym.nnz and asym.max() > 1e-12 * max(1.0, float(abs(C).max())):
        raise InvalidInputError(f"`{name}` must be symmetric (an undirected graph).")
    return C


@dataclass(frozen=True, eq=False)
class Submeshes:
    """Overlapped submeshes of a graph with ``n_vertices`` vertices: sorted global indices
    ``parts[i]`` (n_i,), the METIS ``cores[i]`` they grew from (a partition of the vertices) and the
    in-submesh ``degrees[i]`` (n_i,), the weights of Algorithm 8.
    """

    parts: list[np.ndarray]
    cores: list[np.ndarray]
    n_vertices: int
    degrees: list[np.ndarray] | None = None

    def __len__(self) -> int:
        return len(self.parts)

    @property
    def n_submeshes(self) -> int:
        return len(self.parts)

    @property
    def sizes(self) -> np.ndarray:
        """(n_submeshes,) number of vertices of each submesh."""
        return np.array([p.size for p in self.parts], dtype=np.int64)

    def multiplicity(self) -> np.ndarray:
        """(n_vertices,) number of submeshes each vertex belongs to (``p_i`` of Algorithm 8)."""
        return np.bincount(np.concatenate(self.parts), minlength=self.n_vertices)

    def sub_adjacency(self, C, i: int) -> sp.csr_matrix:
        """Adjacency ``C[part, part]`` of submesh ``i`` (rows/columns in the order of ``parts[i]``)."""
        i = self._index(i)
        C = sp.csr_matrix(C)
        if C.shape != (self.n_vertices, self.n_vertices):
            raise InvalidInputError(
                f"`C` must have shape ({self.n_vertices}, {self.n_vertices}); got {C.shape}."
            )
        return induced_subgraph(C, self.parts[i])

    def _index(self, i: int) -> int:
        if isinstance(i, bool) or not isinstance(i, (int, np.integer)):
            raise InvalidInputError(f"`i` must be an integer submesh index; got {i!r}.")
        if not -len(self.parts) <= i < len(self.parts):
            raise InvalidInputError(f"`i` must be in 0..{len(self.parts) - 1}; got {i}.")
        return int(i) % len(self.parts)


def induced_subgraph(C: sp.csr_matrix, part: np.ndarray) -> sp.csr_matrix:
    """``C[part][:, part]`` for a CSR ``C`` in O(nnz of the selected rows) (no O(n) column mask)."""
    part = np.asarray(part, dtype=np.int64)
    rows = C[part]
    gmap = np.full(C.shape[1], -1, dtype=np.int64)
    gmap[part] = np.arange(part.size)
    cols = gmap[rows.indices]
    keep = cols >= 0
    r = np.repeat(np.arange(part.size), np.diff(rows.indptr))
    return sp.csr_matrix((rows.data[keep], (r[keep], cols[keep])), shape=(part.size, part.size))


def submesh_laplacian(
    graph, part, *, kind: str = "binary", normalized: bool = False, sigma: float | None = None
) -> sp.csr_matrix:
    """Laplacian ``L = D - C_part`` (n_i, n_i) of the subgraph induced by ``part`` (Eq. 4.1).

    ``graph`` is an adjacency (``kind`` ``"binary"``: its pattern; ``"weighted"``: its values) or a
    mesh ``(V, F)`` (``"binary"``, ``"gaussian"``, ``"cotangent"``, Eq. 4.2). Rows follow ``part``;
    ``normalized`` returns ``D^-1/2 L D^-1/2``.
    """
    from ..graph import laplacian_from_adjacency, weighted_adjacency

    if isinstance(graph, tuple):
        if len(graph) != 2:
            raise InvalidInputError("`graph` must be a sparse adjacency or a tuple (V, F).")
        check_choice(kind, "kind", ("binary", "gaussian", "cotangent"))
        V, F = graph
        C = weighted_adjacency(V, F, kind=kind, sigma=sigma).tocsr()
        C.eliminate_zeros()
    else:
        check_choice(kind, "kind", ("binary", "weighted"))
        C = as_adjacency(graph, "graph")
        if kind == "binary":
            C = C.copy()
            C.data[:] = 1.0
    part = _as_part(part, C.shape[0])
    return laplacian_from_adjacency(induced_subgraph(C, part), normalized=normalized)


def _as_part(part, n: int) -> np.ndarray:
    arr = np.asarray(part)
    if arr.ndim != 1 or arr.size == 0 or arr.dtype.kind not in "iu":
        raise InvalidInputError(
            f"`part` must be a non-empty 1-D array of vertex indices; got {arr.dtype} {arr.shape}."
        )
    arr = arr.astype(np.int64)
    if arr.min() < 0 or arr.max() >= n:
        raise InvalidInputError(f"`part` has vertex indices out of range 0..{n - 1}.")
    if np.unique(arr).size != arr.size:
        raise InvalidInputError("`part` has repeated vertex indices.")
    return arr


def overlapped_submeshes(
    C,
    *,
    submesh_size: int = 700,
    overlap: float = 0.15,
    rng=None,
) -> Submeshes:
    """Split a graph into overlapped submeshes of exactly ``submesh_size`` vertices (Section 5.2.1).

    METIS cuts ``ceil(n / (submesh_size (1 - overlap)))`` cores; each grows breadth first by whole
    rings (the last one truncated: more in-submesh neighbours, then lower index), across components
    when needed. The thesis recommends 500-800 vertices and 15 % overlap (Tables 5.8-5.11).

    Parameters
    ----------
    C : sparse (n, n)
        Symmetric adjacency; only its pattern is used.
    submesh_size, overlap, rng
        Vertices of every submesh (>= 2), fraction in [0, 1) grown from neighbouring parts, METIS
        seed. Returns :class:`Submeshes`.
    """
    C = as_adjacency(C)
    check_positive(submesh_size, "submesh_size", integer=True)
    if submesh_size < 2:
        raise InvalidInputError(f"`submesh_size` must be >= 2; got {submesh_size}.")
    if isinstance(overlap, bool) or not isinstance(overlap, (int, float, np.integer, np.floating)):
        raise InvalidInputError(f"`overlap` must be a number in [0, 1); got {overlap!r}.")
    if not 0.0 <= float(overlap) < 1.0:
        raise InvalidInputError(f"`overlap` must be in [0, 1); got {overlap!r}.")
    gen = as_rng(rng)
    n = C.shape[0]
    submesh_size = int(submesh_size)
    pattern = C.copy()
    pattern.data[:] = 1.0

    if n <= submesh_size:
        allv = np.arange(n, dtype=np.int64)
        deg = np.diff(pattern.indptr).astype(np.int64)
        return Submeshes([allv], [allv.copy()], n, [deg])

    cores = metis_cores(pattern, submesh_size, overlap, int(gen.integers(0, 2**31 - 1)))
    marker = np.zeros(n, dtype=bool)
    parts, degrees = [], []
    for core in cores:
        part = _grow(pattern, core, submesh_size, marker)
        parts.append(part)
        degrees.append(np.diff(induced_subgraph(pattern, part).indptr).astype(np.int64))
    return Submeshes(parts, cores, n, degrees)


def metis_cores(pattern: sp.csr_matrix, size: int, overlap: float, seed: int) -> list[np.ndarray]:
    """METIS parts of at most ``size`` vertices: the cores of :func:`overlapped_submeshes`."""
    n = pattern.shape[0]
    n_parts = max(2, math.ceil(n / (size * (1.0 - float(overlap)))))
    for _ in range(8):
        cores = _split(_metis(pattern, n_parts, seed), n_parts)
        biggest = max(c.size for c in cores)
        if biggest <= size:
            return cores
        n_parts = math.ceil(n_parts * biggest / size) + 1
    raise InvalidInputError(  # pragma: no cover - METIS keeps the imbalance within a few percent
        f"could not split the graph into parts of at most `submesh_size` = {size} vertices."
    )


@contextlib.contextmanager
def _quiet_c_stdout():
    """Silence file descriptor 1 (METIS prints notes from C into JSON output)."""
    try:
        if sys.stdout is not None:
            sys.stdout.flush()
        null = os.open(os.devnull, os.O_WRONLY)
    except (OSError, ValueError):  # a closed stream or no null device
        yield
        return
    try:
        saved = os.dup(1)
    except OSError:  # no descriptor 1 (a daemon)
        os.close(null)
        yield
        return
    try:
        os.dup2(null, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


def _metis(pattern: sp.csr_matrix, n_parts: int, seed: int) -> np.ndarray:
    import pymetis

    opts = pymetis.Options(seed=seed)
    adj = pymetis.CSRAdjacency(pattern.indptr.astype(np.int32), pattern.indices.astype(np.int32))
    with _quiet_c_stdout():
        _, membership = pymetis.part_graph(n_parts, adjacency=adj, options=opts)
    return np.asarray(membership, dtype=np.int64)


def _split(membership: np.ndarray, n_parts: int) -> list[np.ndarray]:
    order = np.argsort(membership, kind="stable")
    counts = np.bincount(membership, minlength=n_parts)
    return [c for c in np.split(order, np.cumsum(counts)[:-1]) if c.size]


def _grow(C: sp.csr_matrix, core: np.ndarray, size: int, marker: np.ndarray) -> np.ndarray:
    """Breadth-first growth of ``core`` to exactly ``size`` vertices (``marker`` is scratch, all False)."""
    indptr, indices = C.indptr, C.indices
    chosen = [core]
    marker[core] = True
    count = core.size
    frontier = core
    while count < size:
        nb = _neighbours(indptr, indices, frontier)
        ring = np.unique(nb[~marker[nb]])
        if ring.size == 0:
            # component exhausted: restart from the unvisited vertex closest in index to the core
            free = np.flatnonzero(~marker)
            ring = free[[int(np.argmin(np.abs(free - core[0])))]]
        need = size - count
        if ring.size > need:
            # most neighbours already inside first, then lower index
            lens = indptr[ring + 1] - indptr[ring]
            inside = np.bincount(
                np.repeat(np.arange(ring.size), lens),
                weights=marker[_neighbours(indptr, indices, ring)],
                minlength=ring.size,
            )
            ring = ring[np.lexsort((ring, -inside))[:need]]
        marker[ring] = True
        chosen.append(ring)
        count += ring.size
        frontier = ring
    part = np.sort(np.concatenate(chosen))
    marker[part] = False
    return part


def _neighbours(indptr: np.ndarray, indices: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Concatenated adjacency lists of ``rows`` (vectorised CSR row gather)."""
    starts, ends = indptr[rows], indptr[rows + 1]
    lens = ends - starts
    total = int(lens.sum())
    if total == 0:
        return np.zeros(0, dtype=indices.dtype)
    offs = np.repeat(starts - np.r_[0, np.cumsum(lens)[:-1]], lens)
    return indices[np.arange(total) + offs]


def reassemble(
    values: Sequence[np.ndarray],
    subs: Submeshes,
    *,
    weights: str | Sequence[np.ndarray] | None = None,
) -> np.ndarray:
    """Weighted average of per-submesh results onto the whole graph (Algorithm 8).

    Vertex ``i`` gets ``sum_j w_ij v_ij / sum_j w_ij``, ``w_ij`` its degree in submesh ``j``
    (Figs. 5.49-5.50), taken relative to its core's value so that agreeing submeshes reproduce the
    input bit for bit.

    Parameters
    ----------
    values : list of (n_i,) or (n_i, d) arrays
        One row per vertex of ``subs.parts[j]``; the result is (n,) or (n, d).
    subs : Submeshes
    weights : None, "degree", "uniform", "core" or list of (n_i,) arrays
        Algorithm 8 (default), plain average, the core's value, or explicit weights.
    """
    if not isinstance(subs, Submeshes):
        raise InvalidInputError(f"`subs` must be a Submeshes; got {type(subs).__name__}.")
    if not isinstance(values, Sequence) or isinstance(values, np.ndarray):
        raise InvalidInputError("`values` must be a list with one array per submesh.")
    m = len(subs.parts)
    if len(values) != m:
        raise InvalidInputError(
            f"`values` must hold {m} arrays (one per submesh); got {len(values)}."
        )
    vals = []
    tail = None
    for j, (v, part) in enumerate(zip(values, subs.parts)):
        a = np.asarray(v, dtype=np.float64)
        if a.ndim not in (1, 2) or a.shape[0] != part.size:
            raise InvalidInputError(
                f"`values[{j}]` must have {part.size} rows (one per vertex of the submesh); "
                f"got shape {a.shape}."
            )
        if tail is None:
            tail = a.shape[1:]
        elif a.shape[1:] != tail:
            raise InvalidInputError(
                f"`values[{j}]` has trailing shape {a.shape[1:]}; expected {tail} like `values[0]`."
            )
        if not np.isfinite(a).all():
            raise InvalidInputError(f"`values[{j}]` contains NaN or inf.")
        vals.append(a.reshape(part.size, -1))
    n = subs.n_vertices
    d = vals[0].shape[1]

    # reference value: the copy from the submesh whose core holds the vertex
    owner = np.empty(n, dtype=np.int64)
    for j, core in enumerate(subs.cores):
        owner[core] = j
    allp = np.concatenate(subs.parts)
    sub_id = np.repeat(np.arange(m), [p.size for p in subs.parts])
    X = np.concatenate(vals, axis=0)
    ref_rows = np.flatnonzero(owner[allp] == sub_id)
    ref = np.empty((n, d))
    ref[allp[ref_rows]] = X[ref_rows]

    if isinstance(weights, str):
        check_choice(weights, "weights", ("degree", "uniform", "core"))
        mode = weights
    elif weights is None:
        mode = "degree"
    else:
        mode = "explicit"
    if mode == "core":
        return ref.reshape((n,) + tail)
    if mode == "degree":
        if subs.degrees is None:
            raise InvalidInputError(
                "`subs` carries no degrees; build it with `overlapped_submeshes` or pass `weights`."
            )
        w = np.concatenate(subs.degrees).astype(np.float64)
    elif mode == "uniform":
        w = np.ones(allp.size)
    else:
        if len(weights) != m:
            raise InvalidInputError(f"`weights` must hold {m} arrays; got {len(weights)}.")
        ws = []
        for j, (wj, part) in enumerate(zip(weights, subs.parts)):
            a = np.asarray(wj, dtype=np.float64)
            if a.shape != (part.size,):
                raise InvalidInputError(
                    f"`weights[{j}]` must have shape ({part.size},); got {a.shape}."
                )
            if not np.isfinite(a).all() or (a < 0).any():
                raise InvalidInputError(f"`weights[{j}]` must be finite and non-negative.")
            ws.append(a)
        w = np.concatenate(ws)
    wsum = np.bincount(allp, weights=w, minlength=n)
    zero = wsum[allp] == 0
    if zero.any():  # all weights zero for these vertices: plain average
        w = np.where(zero, 1.0, w)
        wsum = np.bincount(allp, weights=w, minlength=n)
    S = sp.csr_matrix((w, (allp, np.arange(allp.size))), shape=(n, allp.size))
    acc = S @ (X - ref[allp])
    out = ref + acc / wsum[:, None]
    return out.reshape((n,) + tail)
