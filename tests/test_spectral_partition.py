"""Overlapped equal-sized submeshes (Section 5.2.1) and the degree-weighted reassembly (Algorithm 8)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, shortest_path

from spectrageo._errors import InvalidInputError
from spectrageo.datasets import fandisk
from spectrageo.graph import adjacency_matrix, mesh_laplacian, weighted_adjacency
from spectrageo.spectral import Submeshes, overlapped_submeshes, reassemble, submesh_laplacian

from conftest import grid


@pytest.fixture(scope="module")
def fandisk_graph():
    m = fandisk()
    V, F = m.vertices, m.faces
    return V, F, adjacency_matrix(F, V.shape[0])


def _path_graph(n: int, offset: int = 0, total: int | None = None) -> sp.csr_matrix:
    total = n + offset if total is None else total
    i = np.arange(offset, offset + n - 1)
    return sp.csr_matrix(
        (np.ones(2 * i.size), (np.r_[i, i + 1], np.r_[i + 1, i])), shape=(total,) * 2
    )


def _disjoint(*graphs: sp.spmatrix) -> sp.csr_matrix:
    return sp.block_diag(graphs, format="csr")


def _check_invariants(subs: Submeshes, C: sp.csr_matrix, size: int) -> None:
    n = C.shape[0]
    assert subs.n_vertices == n
    # cores partition the vertex set
    allc = np.concatenate(subs.cores)
    assert np.array_equal(np.sort(allc), np.arange(n))
    # parts: sorted unique indices, exactly `size` vertices, cover everything, contain their core
    for part, core in zip(subs.parts, subs.cores):
        assert part.size == min(size, n)
        assert np.all(np.diff(part) > 0)
        assert np.isin(core, part).all()
    assert (subs.multiplicity() >= 1).all()
    # degrees of Algorithm 8 = degree inside the induced subgraph, recomputed independently
    for part, deg in zip(subs.parts, subs.degrees):
        sub = C[part][:, part]
        assert np.array_equal(deg, np.diff(sub.tocsr().indptr))


def test_fandisk_parts_equal_size_cover_and_overlap(fandisk_graph):
    V, F, C = fandisk_graph
    n = V.shape[0]
    subs = overlapped_submeshes(C, submesh_size=700, overlap=0.15, rng=0)
    # n_parts = ceil(n / (700 * 0.85))
    assert len(subs) == int(np.ceil(n / (700 * 0.85)))
    _check_invariants(subs, C, 700)
    # about 15 % of every submesh comes from neighbouring parts
    frac = np.array([1 - c.size / p.size for c, p in zip(subs.cores, subs.parts)])
    assert 0.08 < frac.mean() < 0.22
    assert subs.multiplicity().max() >= 2


def test_growth_is_breadth_first(fandisk_graph):
    """Every grown part holds all vertices closer to its core than its farthest vertex."""
    _, _, C = fandisk_graph
    subs = overlapped_submeshes(C, submesh_size=500, overlap=0.2, rng=1)
    for part, core in zip(subs.parts[:4], subs.cores[:4]):
        dist = shortest_path(C, unweighted=True, indices=core, directed=False).min(axis=0)
        r = dist[part].max()
        assert r >= 1
        inside = np.zeros(C.shape[0], dtype=bool)
        inside[part] = True
        assert inside[dist < r].all()  # whole inner rings are included
        assert (dist[part] <= r).all()


def test_grid_and_single_part_cases():
    V, F = grid(12, 12)
    C = adjacency_matrix(F, V.shape[0])
    subs = overlapped_submeshes(C, submesh_size=50, overlap=0.15)
    _check_invariants(subs, C, 50)
    # n < submesh_size and n == submesh_size: one part, the whole graph
    for size in (144, 500):
        one = overlapped_submeshes(C, submesh_size=size)
        assert len(one) == 1
        assert np.array_equal(one.parts[0], np.arange(144))
        assert np.array_equal(one.cores[0], np.arange(144))


def test_several_components_and_tiny_ones():
    # two paths of 150 and 90 vertices, a triangle and two isolated vertices
    tri = sp.csr_matrix(np.ones((3, 3)) - np.eye(3))
    C = _disjoint(_path_graph(150), _path_graph(90), tri, sp.csr_matrix((2, 2)))
    n = C.shape[0]
    assert connected_components(C)[0] == 5
    subs = overlapped_submeshes(C, submesh_size=60, overlap=0.25, rng=3)
    _check_invariants(subs, C, 60)
    # a component smaller than the submesh size is completed from other components
    small = overlapped_submeshes(_disjoint(_path_graph(40), _path_graph(40), tri), submesh_size=50)
    assert set(small.sizes.tolist()) == {50}
    assert n == 245


def test_deterministic_for_a_seed(fandisk_graph):
    _, _, C = fandisk_graph
    a = overlapped_submeshes(C, submesh_size=600, rng=7)
    b = overlapped_submeshes(C, submesh_size=600, rng=7)
    assert len(a) == len(b)
    assert all(np.array_equal(x, y) for x, y in zip(a.parts, b.parts))
    assert all(np.array_equal(x, y) for x, y in zip(a.cores, b.cores))


def test_zero_overlap_keeps_equal_sizes(fandisk_graph):
    _, _, C = fandisk_graph
    subs = overlapped_submeshes(C, submesh_size=700, overlap=0.0)
    _check_invariants(subs, C, 700)


def test_identity_reassembles_exactly(fandisk_graph):
    V, _, C = fandisk_graph
    subs = overlapped_submeshes(C, submesh_size=700)
    vals = [V[p] for p in subs.parts]
    for weights in (None, "degree", "uniform", "core"):
        assert np.array_equal(reassemble(vals, subs, weights=weights), V)
    rng = np.random.default_rng(0)
    explicit = [rng.random(p.size) for p in subs.parts]
    assert np.array_equal(reassemble(vals, subs, weights=explicit), V)
    # 1-D signals keep their shape
    x = V[:, 2].copy()
    assert np.array_equal(reassemble([x[p] for p in subs.parts], subs), x)


def test_weighted_average_matches_algorithm_8_loop():
    V, F = grid(9, 9)
    C = adjacency_matrix(F, V.shape[0])
    subs = overlapped_submeshes(C, submesh_size=30, overlap=0.3, rng=2)
    rng = np.random.default_rng(5)
    vals = [rng.normal(size=(p.size, 2)) for p in subs.parts]
    out = reassemble(vals, subs)
    # literal Algorithm 8: loop over points, then over the submeshes that contain them
    Cd = C.toarray()
    for i in range(V.shape[0]):
        sumv, sumw = np.zeros(2), 0.0
        for j, part in enumerate(subs.parts):
            pos = np.flatnonzero(part == i)
            if pos.size:
                w = Cd[i, part].sum()  # degree of i inside submesh j
                sumv += w * vals[j][pos[0]]
                sumw += w
        np.testing.assert_allclose(out[i], sumv / sumw, rtol=1e-12, atol=1e-14)
    # the uniform variant is the plain mean of the copies
    uni = reassemble(vals, subs, weights="uniform")
    i = int(np.argmax(subs.multiplicity()))
    copies = [vals[j][np.flatnonzero(p == i)[0]] for j, p in enumerate(subs.parts) if i in p]
    np.testing.assert_allclose(uni[i], np.mean(copies, axis=0), rtol=1e-12)


def test_isolated_vertex_gets_plain_average():
    C = _disjoint(_path_graph(20), sp.csr_matrix((1, 1)))  # vertex 20 is isolated
    subs = overlapped_submeshes(C, submesh_size=12, overlap=0.3)
    vals = [np.full(p.size, float(j)) for j, p in enumerate(subs.parts)]
    out = reassemble(vals, subs)
    holders = [j for j, p in enumerate(subs.parts) if 20 in p]
    assert holders
    assert out[20] == pytest.approx(np.mean(holders))
    # every vertex gets a convex combination of the part indices holding it
    assert np.isfinite(out).all()
    for i in range(out.size):
        held = [j for j, p in enumerate(subs.parts) if i in p]
        assert min(held) - 1e-12 <= out[i] <= max(held) + 1e-12


def test_submesh_laplacian_kinds(fandisk_graph):
    V, F, C = fandisk_graph
    subs = overlapped_submeshes(C, submesh_size=700)
    part = subs.parts[1]
    L = submesh_laplacian(C, part)
    sub = C[part][:, part]
    expected = sp.diags(np.asarray(sub.sum(axis=1)).ravel()) - sub
    assert abs(L - expected).max() == 0
    assert np.allclose(L @ np.ones(part.size), 0)
    assert abs(L - L.T).max() == 0
    np.testing.assert_array_equal(subs.sub_adjacency(C, 1).toarray(), sub.toarray())
    # (V, F) with cotangent / gaussian weights: whole-mesh weights restricted to the submesh
    for kind in ("cotangent", "gaussian"):
        Lk = submesh_laplacian((V, F), part, kind=kind)
        W = weighted_adjacency(V, F, kind=kind)[part][:, part]
        off = -(Lk - sp.diags(Lk.diagonal()))
        np.testing.assert_allclose(off.toarray(), W.toarray(), atol=1e-12)
        np.testing.assert_allclose(Lk @ np.ones(part.size), 0, atol=1e-10)
    # on the whole vertex set the submesh Laplacian is the mesh Laplacian
    allv = np.arange(V.shape[0])
    assert abs(submesh_laplacian((V, F), allv) - mesh_laplacian(V, F)).max() < 1e-12
    # weighted kind uses the values of C
    Cw = C.copy()
    Cw.data = np.arange(1, Cw.nnz + 1, dtype=float)
    Cw = (Cw + Cw.T).tocsr()
    Lw = submesh_laplacian(Cw, part, kind="weighted")
    subw = Cw[part][:, part]
    assert abs(Lw - (sp.diags(np.asarray(subw.sum(axis=1)).ravel()) - subw)).max() < 1e-9
    Ln = submesh_laplacian(C, part, normalized=True)
    np.testing.assert_allclose(Ln.diagonal()[np.diff(sub.indptr) > 0], 1.0)


# ------------------------------------------------------------------------------- validation
def test_validation_adjacency():
    with pytest.raises(InvalidInputError, match="scipy.sparse adjacency"):
        overlapped_submeshes(np.eye(3))
    with pytest.raises(InvalidInputError, match="must be square"):
        overlapped_submeshes(sp.csr_matrix((3, 4)))
    with pytest.raises(InvalidInputError, match="is empty"):
        overlapped_submeshes(sp.csr_matrix((0, 0)))
    with pytest.raises(InvalidInputError, match="symmetric"):
        overlapped_submeshes(sp.csr_matrix(np.triu(np.ones((4, 4)), 1)))
    with pytest.raises(InvalidInputError, match="non-negative"):
        overlapped_submeshes(sp.csr_matrix(-(np.ones((3, 3)) - np.eye(3))))
    bad = sp.csr_matrix(np.ones((3, 3)) - np.eye(3))
    bad.data[0] = np.nan
    with pytest.raises(InvalidInputError, match="NaN"):
        overlapped_submeshes(bad)


def test_validation_sizes():
    C = _path_graph(30)
    with pytest.raises(InvalidInputError, match="`submesh_size` must be an integer"):
        overlapped_submeshes(C, submesh_size=10.5)
    with pytest.raises(InvalidInputError, match="`submesh_size` must be >= 2"):
        overlapped_submeshes(C, submesh_size=1)
    with pytest.raises(InvalidInputError, match="`submesh_size` must be > 0"):
        overlapped_submeshes(C, submesh_size=0)
    with pytest.raises(InvalidInputError, match=r"`overlap` must be in \[0, 1\)"):
        overlapped_submeshes(C, overlap=1.0)
    with pytest.raises(InvalidInputError, match=r"`overlap` must be in \[0, 1\)"):
        overlapped_submeshes(C, overlap=-0.1)
    with pytest.raises(InvalidInputError, match="`overlap` must be a number"):
        overlapped_submeshes(C, overlap="a")
    with pytest.raises(InvalidInputError, match="`rng` must be"):
        overlapped_submeshes(C, rng="seed")


def test_validation_reassemble():
    C = _path_graph(30)
    subs = overlapped_submeshes(C, submesh_size=12)
    x = np.arange(30.0)
    vals = [x[p] for p in subs.parts]
    with pytest.raises(InvalidInputError, match="`subs` must be a Submeshes"):
        reassemble(vals, "subs")
    with pytest.raises(InvalidInputError, match="one array per submesh"):
        reassemble(np.zeros(3), subs)
    with pytest.raises(InvalidInputError, match=f"must hold {len(subs)} arrays"):
        reassemble(vals[:-1], subs)
    with pytest.raises(InvalidInputError, match=r"`values\[0\]` must have 12 rows"):
        reassemble([np.zeros(5)] + vals[1:], subs)
    with pytest.raises(InvalidInputError, match="trailing shape"):
        reassemble([vals[0][:, None].repeat(2, 1)] + vals[1:], subs)
    with pytest.raises(InvalidInputError, match="NaN or inf"):
        reassemble([np.full(12, np.nan)] + vals[1:], subs)
    with pytest.raises(InvalidInputError, match="`weights` must be one of"):
        reassemble(vals, subs, weights="bogus")
    with pytest.raises(InvalidInputError, match="`weights` must hold"):
        reassemble(vals, subs, weights=[np.ones(12)])
    with pytest.raises(InvalidInputError, match=r"`weights\[0\]` must have shape"):
        reassemble(vals, subs, weights=[np.ones(3)] * len(subs))
    with pytest.raises(InvalidInputError, match="finite and non-negative"):
        reassemble(vals, subs, weights=[-np.ones(12)] * len(subs))
    bare = Submeshes(subs.parts, subs.cores, subs.n_vertices)
    with pytest.raises(InvalidInputError, match="carries no degrees"):
        reassemble(vals, bare)
    assert np.array_equal(reassemble(vals, bare, weights="uniform"), x)


def test_validation_submesh_helpers():
    C = _path_graph(30)
    subs = overlapped_submeshes(C, submesh_size=12)
    with pytest.raises(InvalidInputError, match="`i` must be in"):
        subs.sub_adjacency(C, 99)
    with pytest.raises(InvalidInputError, match="`i` must be an integer"):
        subs.sub_adjacency(C, 1.5)
    with pytest.raises(InvalidInputError, match="`C` must have shape"):
        subs.sub_adjacency(_path_graph(10), 0)
    with pytest.raises(InvalidInputError, match="`part` must be a non-empty 1-D"):
        submesh_laplacian(C, np.array([], dtype=int))
    with pytest.raises(InvalidInputError, match="out of range"):
        submesh_laplacian(C, np.array([0, 40]))
    with pytest.raises(InvalidInputError, match="repeated"):
        submesh_laplacian(C, np.array([1, 1]))
    with pytest.raises(InvalidInputError, match="`kind` must be one of"):
        submesh_laplacian(C, np.arange(3), kind="cotangent")
    with pytest.raises(InvalidInputError, match="tuple"):
        submesh_laplacian((1, 2, 3), np.arange(3))


def test_metis_notes_do_not_reach_standard_output(capfd):
    """METIS prints notes ("***You are trying to partition a graph into too many parts!") from C
    straight to descriptor 1, where they mixed with a command's own output; the partition
    silences that descriptor for the call only and restores it."""
    import os

    from spectrageo.spectral.partition import _quiet_c_stdout

    os.write(1, b"before\n")
    with _quiet_c_stdout():
        os.write(1, b"***a note from C\n")
    os.write(1, b"after\n")
    out = capfd.readouterr().out
    assert out == "before\nafter\n"
