"""Organized depth frames (OrganizedGrid, PCD grid and VIEWPOINT) and sparse surface regions."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo._errors import InvalidInputError
from spectrageo.outliers import OrganizedGrid, RPCAOptions, detect_outliers, scan_options


def _frame(h: int = 60, w: int = 80, edge: int = 40, seed: int = 0):
    """A pinhole frame: a wall at depth 1 left of column ``edge``, one at depth 2 right of it,
    and the column ``edge`` of mixed (flying) pixels at depth 1.5; returns (points, flying)."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:h, 0:w]
    z = np.where(u < edge, 1.0, 2.0)
    z[:, edge] = 1.5
    z = z + rng.normal(0.0, 2e-4, z.shape)
    f = 100.0
    P = np.stack([(u - w / 2) / f * z, (v - h / 2) / f * z, z], axis=-1).reshape(-1, 3)
    return P, (u == edge).reshape(-1)


def test_grid_labels_find_the_flying_pixels_between_two_walls():
    from spectrageo.outliers._organized import grid_labels

    P, fly = _frame()
    supported, flying = grid_labels(P, np.arange(P.shape[0]), (60, 80))
    np.testing.assert_array_equal(flying, fly)
    assert supported[~fly].mean() > 0.9 and not supported[fly].any()


def test_remove_outliers_with_a_grid_removes_flying_pixels_and_keeps_the_walls():
    from spectrageo import noise

    P, fly = _frame()
    r = detect_outliers(P, options=RPCAOptions(grid=OrganizedGrid((60, 80))))
    assert r.info["n_flying"] == fly.sum()
    assert not r.keep[fly].any()
    assert r.keep[~fly].mean() >= 0.99
    # points added off the grid (index -1) are judged by the scores alone
    Q, lab = noise.add_outliers(P, fraction=0.05, kind="far", rng=1)
    index = np.concatenate([np.arange(P.shape[0]), np.full(Q.shape[0] - P.shape[0], -1)])
    r = detect_outliers(Q, options=RPCAOptions(grid=OrganizedGrid((60, 80), index)))
    assert np.count_nonzero(~r.keep & lab) >= 0.95 * lab.sum()
    assert not r.keep[: P.shape[0]][fly].any()


def test_organized_grid_checks():
    with pytest.raises(InvalidInputError, match="shape"):
        OrganizedGrid((0, 4))
    with pytest.raises(InvalidInputError, match="outside"):
        OrganizedGrid((2, 2), [0, 4])
    with pytest.raises(InvalidInputError, match="same pixel"):
        OrganizedGrid((2, 2), [1, 1])
    with pytest.raises(InvalidInputError, match="OrganizedGrid"):
        RPCAOptions(grid=(2, 2))
    P, _ = _frame(10, 10, 5)
    with pytest.raises(InvalidInputError, match="entries"):
        detect_outliers(P, options=RPCAOptions(grid=OrganizedGrid((10, 10), np.arange(50))))
    with pytest.raises(InvalidInputError, match="height \\* width"):
        detect_outliers(P[:90], options=RPCAOptions(grid=OrganizedGrid((10, 10))))


def _organized_pcd(path, P, h, w, viewpoint="0 0 0 1 0 0 0"):
    from spectrageo.io._pcd import write_pcd

    raw = write_pcd(P.astype(np.float32), pcd_format="binary_compressed")
    raw = raw.replace(f"WIDTH {P.shape[0]}\nHEIGHT 1".encode(), f"WIDTH {w}\nHEIGHT {h}".encode())
    raw = raw.replace(b"VIEWPOINT 0 0 0 1 0 0 0", f"VIEWPOINT {viewpoint}".encode())
    path.write_bytes(raw)
    return path


def test_pcd_header_grid_and_viewpoint(tmp_path):
    import gzip

    from spectrageo import io
    from spectrageo.io._pcd import read_pcd_header

    P, _ = _frame()
    P[[5, 77]] = np.nan  # missing pixels
    f = _organized_pcd(tmp_path / "frame.pcd", P, 60, 80, "0.5 0 -1 0 1 0 0")
    hdr = read_pcd_header(f)
    assert (hdr.width, hdr.height, hdr.organized) == (80, 60, True)
    assert hdr.origin == (0.5, 0.0, -1.0) and not hdr.default_viewpoint
    g = tmp_path / "frame.pcd.gz"
    g.write_bytes(gzip.compress(f.read_bytes()))
    assert read_pcd_header(g) == hdr
    cloud = io.read(f)
    opts = scan_options(f, cloud)
    assert opts.viewpoint == (0.5, 0.0, -1.0) and opts.grid.shape == (60, 80)
    np.testing.assert_array_equal(opts.grid.index, np.delete(np.arange(4800), [5, 77]))
    assert scan_options(f, cloud, "1,2,3").viewpoint == (1.0, 2.0, 3.0)  # the user's wins
    assert scan_options(f, cloud, method="sor") is None
    flat = _organized_pcd(tmp_path / "flat.pcd", np.nan_to_num(P), 1, 4800)
    assert scan_options(flat, io.read(flat)) is None  # unorganized, default VIEWPOINT
    bad = tmp_path / "bad.pcd"
    bad.write_bytes(f.read_bytes().replace(b"VIEWPOINT 0.5 0 -1", b"VIEWPOINT 0.5 0 x"))
    with pytest.raises(InvalidInputError, match="VIEWPOINT"):
        read_pcd_header(bad)


def test_cli_outliers_uses_the_pcd_grid(tmp_path):
    from spectrageo.cli.main import main

    P, fly = _frame()
    P[3] = np.nan
    f = _organized_pcd(tmp_path / "frame.pcd", P, 60, 80)
    mask = tmp_path / "keep.npy"
    assert main(["outliers", str(f), str(tmp_path / "out.pcd"), "--mask", str(mask)]) == 0
    keep = np.load(mask)
    assert keep.shape == (4800,) and not keep[3] and not keep[fly].any()
    assert keep[~fly].mean() >= 0.99


def test_sparse_surface_region_is_kept_and_near_outliers_still_removed():
    """A plane sampled 4x more sparsely next to a dense one is a surface (do no harm); outliers
    5-15 spacings off the planes are still found."""
    from spectrageo import noise

    rng = np.random.default_rng(7)
    dense = np.column_stack([rng.uniform(0, 1, (16000, 2)), np.zeros(16000)])
    sparse = np.column_stack([rng.uniform(1, 2, (1000, 1)), rng.uniform(0, 1, (1000, 1))])
    sparse = np.column_stack([sparse, np.zeros(1000)])
    P = np.concatenate([dense, sparse])
    P[:, 2] += rng.normal(0.0, 1e-4, P.shape[0])
    r = detect_outliers(P)
    assert (~r.keep[16000:]).mean() <= 0.05
    N = np.tile([0.0, 0.0, 1.0], (P.shape[0], 1))
    Q, lab = noise.add_outliers(P, fraction=0.1, kind="near", distance=(5, 15), normals=N, rng=3)
    r = detect_outliers(Q)
    assert np.count_nonzero(~r.keep & lab) >= 0.8 * lab.sum()


def test_sparse_surface_with_the_scores_neighbours_matches_a_tree_search():
    from spectrageo import noise
    from spectrageo.outliers._support import sparse_surface
    from spectrageo.outliers.rpca import rpca_scores

    rng = np.random.default_rng(2)
    P = np.column_stack([rng.uniform(0, 1, (3000, 2)), np.zeros(3000)])
    P = np.concatenate([P, np.column_stack([rng.uniform(1, 2, (300, 2)), np.zeros(300)])])
    Q, _ = noise.add_outliers(P, fraction=0.1, kind="far", rng=4)
    res = rpca_scores(Q, 10)
    removed = res.scores >= 1.0
    np.testing.assert_array_equal(
        sparse_surface(Q, removed, 10, res.knn), sparse_surface(Q, removed, 10)
    )
    assert sparse_surface(Q, removed, 10).any()
