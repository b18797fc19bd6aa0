"""Spectral codec kernels: full eigenbases applied without forming them, threads, compiled growth."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import compress, datasets
from spectrageo.compress import _spectral, _spectral_fast
from spectrageo.graph import adjacency_matrix
from spectrageo.spectral import overlapped_submeshes
from spectrageo.spectral.partition import induced_subgraph

from conftest import grid, icosphere


@pytest.fixture(scope="module")
def fandisk():
    m = datasets.fandisk()
    return m.vertices, m.faces


def _two_pieces():
    """Two disjoint meshes (a sphere and a grid) plus an unreferenced vertex: several components."""
    V1, F1 = icosphere(3)
    V2, F2 = grid(12, 9)
    V = np.vstack([V1, V2 + 3.0, [[9.0, 9.0, 9.0]]])
    F = np.vstack([F1, F2 + len(V1)])
    return V, F


@pytest.mark.parametrize("size,overlap", [(64, 0.1), (100, 0.3), (300, 0.1)])
def test_compiled_growth_matches_reference(fandisk, size, overlap):
    for V, F in (fandisk, _two_pieces()):
        C = adjacency_matrix(F, len(V))
        a = overlapped_submeshes(C, submesh_size=size, overlap=overlap, rng=3)
        b = _spectral_fast.overlapped_submeshes(C, submesh_size=size, overlap=overlap, rng=3)
        assert len(a) == len(b)
        for x, y in zip(a.parts, b.parts):
            assert np.array_equal(x, y)
        for x, y in zip(a.cores, b.cores):
            assert np.array_equal(x, y)
        for x, y in zip(a.degrees, b.degrees):
            assert np.array_equal(x, y)


def test_full_bases_are_the_laplacian_eigenbases():
    V, F = _two_pieces()
    C = adjacency_matrix(F, len(V))
    subs = _spectral_fast.overlapped_submeshes(C, submesh_size=120, overlap=0.1, rng=0)
    fb = _spectral_fast.FullBases(C, subs.parts, workers=1)
    bases = fb.explicit()
    coefs = fb.analyse(V)
    values = fb.synthesise(coefs)
    for part, U, c, v in zip(subs.parts, bases, coefs, values):
        A = induced_subgraph(C, part)
        A.data[:] = 1.0
        L = np.diag(np.asarray(A.sum(axis=1)).ravel()) - A.toarray()
        w = np.linalg.eigvalsh(L)
        n = len(part)
        assert np.abs(U.T @ U - np.eye(n)).max() < 1e-12
        assert np.abs(L @ U - U * w).max() < 1e-10  # ascending eigenpairs
        assert (U[0] >= 0).all()
        assert np.abs(c - U.T @ V[part]).max() < 1e-12
        assert np.abs(v - V[part]).max() < 1e-12
    # a truncated coefficient set is padded with zeros
    short = [c[: len(c) // 3] for c in coefs]
    for v, U, c in zip(fb.synthesise(short), bases, short):
        assert np.abs(v - U[:, : len(c)] @ c).max() < 1e-12


def test_threads_give_identical_bytes_and_meshes(fandisk, monkeypatch):
    V, F = fandisk
    out = []
    for workers in (1, 2, 3):
        monkeypatch.setattr(_spectral, "WORKERS", workers)
        data = compress.encode(V, F, step=3e-4)
        out.append((data, compress.decode(data)[0]))
    for data, V2 in out[1:]:
        assert data == out[0][0]
        assert np.array_equal(V2, out[0][1])


def test_error_target_uses_the_decoder_basis(fandisk):
    V, F = fandisk
    diag = np.linalg.norm(V.max(0) - V.min(0))
    data = compress.encode(V, F, error=2e-4)
    V2, _ = compress.decode(data)
    err = np.sqrt(np.mean(np.sum((V - V2) ** 2, axis=1))) / diag
    assert abs(err - 2e-4) <= 0.05 * 2e-4


def test_subspace_tracking_path_still_used_below_full_size(fandisk):
    V, F = fandisk
    data = compress.encode(V, F, step=1e-3, submesh_size=200, k=60)
    V2, F2 = compress.decode(data)
    assert np.array_equal(F2, F)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert np.sqrt(np.mean(np.sum((V - V2) ** 2, axis=1))) / diag < 5e-3
    X = (V - V.mean(0)) / diag
    _subs, dic = _spectral.dictionaries(F, len(V), _spectral.SpectralParams(submesh_size=200, k=60))
    assert isinstance(dic, _spectral._Explicit) and set(dic.sizes) == {60}
    full = _spectral.SpectralParams(submesh_size=200, k=200)
    _subs, dic = _spectral.dictionaries(F, len(V), full)
    assert isinstance(dic, _spectral._Explicit)  # no DIRECT_FULL flag: orthogonal iterations
    full.direct = True
    _subs, dic = _spectral.dictionaries(F, len(V), full)
    assert isinstance(dic, _spectral._Full)
    assert len(dic.analyse(X, _subs.parts)) == len(_subs)


def test_dense_fallback_when_the_compiled_decomposition_fails(fandisk, monkeypatch):
    V, F = fandisk
    ref = compress.decode(compress.encode(V, F, step=1e-3))[0]

    def fail(self, kernel, *args):
        raise np.linalg.LinAlgError("forced")

    monkeypatch.setattr(_spectral_fast.FullBases, "_run", fail)
    data = compress.encode(V, F, step=1e-3)
    V2, _ = compress.decode(data)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert np.sqrt(np.mean(np.sum((V2 - ref) ** 2, axis=1))) / diag < 1e-4
    assert np.sqrt(np.mean(np.sum((V2 - V) ** 2, axis=1))) / diag < 1e-3


def test_files_without_the_direct_flag_decode_with_orthogonal_iterations(fandisk, monkeypatch):
    V, F = fandisk
    real = _spectral.dictionaries

    def legacy(F, n, p):
        p.direct = False  # what the encoder wrote before the flag existed
        return real(F, n, p)

    monkeypatch.setattr(_spectral, "dictionaries", legacy)
    data = compress.encode(V, F, step=1e-3)
    monkeypatch.undo()
    assert not _spectral.SpectralParams.from_bytes(compress._container.parse(data).params).direct
    new = compress.encode(V, F, step=1e-3)
    assert _spectral.SpectralParams.from_bytes(compress._container.parse(new).params).direct
    # info says which bases a file was coded with
    assert compress.info(new)["parameters"]["direct"] is True
    assert compress.info(data)["parameters"]["direct"] is False
    diag = np.linalg.norm(V.max(0) - V.min(0))
    for d in (data, new):
        V2, _ = compress.decode(d)
        assert np.sqrt(np.mean(np.sum((V2 - V) ** 2, axis=1))) / diag < 1e-3
    # below the full size no flag is written (the files are the same as before)
    small = compress.encode(V, F, step=1e-3, submesh_size=200, k=60)
    assert not _spectral.SpectralParams.from_bytes(compress._container.parse(small).params).direct


def test_analysis_with_bases_equals_the_two_passes():
    # one decomposition per submesh must give the separate passes' values bit for bit: files
    # written after a max_error / error search equal those of a plain encode at that step
    V, F = _two_pieces()
    C = adjacency_matrix(F, len(V))
    subs = _spectral_fast.overlapped_submeshes(C, submesh_size=90, overlap=0.1, rng=1)
    fb = _spectral_fast.FullBases(C, subs.parts, workers=2)
    coefs, bases = fb.analyse_explicit(V)
    for a, b in zip(coefs, fb.analyse(V)):
        assert np.array_equal(a, b)
    for a, b in zip(bases, fb.explicit()):
        assert np.array_equal(a, b)
