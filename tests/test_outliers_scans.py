"""Outlier removal on real sensor scans: do no harm, the range model, the scan-type benchmark."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo._errors import InvalidInputError
from spectrageo.outliers import RPCAOptions, detect_outliers

from conftest import shared_file


def test_do_no_harm_on_reference_cleaned_range_scan(shared_data):
    """A laser range scan without its real outliers (reference surface): at most 1 % removed,
    and no large connected group of removed points."""
    from spectrageo.evaluate._outliers_scans import _largest_group, real_labels

    shared_file(shared_data, "meshes", "stanford-bunny.obj")
    shared_file(shared_data, "scans", "bunny", "bun000.ply.gz")
    W, lab, h = real_labels(shared_data, "scans/bunny/bun000.ply.gz")
    assert W.shape[0] == 40256 and lab.sum() < 0.001 * W.shape[0]
    P = W[~lab]
    r = detect_outliers(P)
    removed = ~r.keep
    assert removed.mean() <= 0.01
    assert _largest_group(P, removed, h) <= 20


def test_range_model_keeps_far_regions_of_a_kinect_frame(shared_data):
    """An organized Kinect frame (camera coordinates): with the sensor viewpoint, the sparse far
    regions are kept; injected far outliers are still found."""
    from spectrageo import io, noise

    f = shared_file(shared_data, "scans", "pcl", "table_scene_mug_stereo_textured.pcd")
    P = io.read(f, kind="points").points
    plain = detect_outliers(P)
    ranged = detect_outliers(P, options=RPCAOptions(viewpoint=(0, 0, 0)))
    assert ranged.n_removed < 0.25 * plain.n_removed
    assert ranged.n_removed <= 0.015 * P.shape[0]
    Q, lab = noise.add_outliers(P, fraction=0.05, kind="far", rng=0, shuffle=True)
    r = detect_outliers(Q, options=RPCAOptions(viewpoint=(0, 0, 0)))
    assert np.count_nonzero(~r.keep & lab) >= 0.95 * lab.sum()


def test_viewpoint_option_checks_and_identity():
    rng = np.random.default_rng(0)
    P = rng.standard_normal((400, 3))
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    base = detect_outliers(P).scores
    # range power 0 is the plain score; a viewpoint at the centre of a sphere changes nothing
    same = detect_outliers(P, options=RPCAOptions(viewpoint=(0, 0, 0), range_power=0)).scores
    np.testing.assert_array_equal(base, same)
    centred = detect_outliers(P, options=RPCAOptions(viewpoint=(0, 0, 0))).scores
    np.testing.assert_allclose(centred, base, rtol=1e-12)
    with pytest.raises(InvalidInputError, match="viewpoint"):
        RPCAOptions(viewpoint=(0, 0))
    with pytest.raises(InvalidInputError, match="viewpoint"):
        RPCAOptions(viewpoint=(0, np.nan, 0))
    with pytest.raises(InvalidInputError, match="range_power"):
        RPCAOptions(range_power=-1)


def test_scan_type_cases_are_registered():
    from spectrageo.datasets._split_outliers import OUTLIER_SCAN_TYPES
    from spectrageo.evaluate._outliers_scans import SCAN_TYPE_CASES

    files = {f for _, f, _ in SCAN_TYPE_CASES}
    assert files == set(OUTLIER_SCAN_TYPES)
    splits = {s for _, _, s in SCAN_TYPE_CASES}
    assert splits == {"tuning", "validation"}


def test_scan_type_benchmark_rows_and_table(shared_data, monkeypatch):
    """One Kinect case: clean, injected and band rows for ours and the peers, and the summary."""
    import spectrageo.evaluate._outliers_scans as ev

    shared_file(shared_data, "scans", "pcl", "milk.pcd")
    case = next(c for c in ev.SCAN_TYPE_CASES if c[1] == "scans/pcl/milk.pcd")
    monkeypatch.setattr(ev, "SCAN_TYPE_CASES", (case,))
    monkeypatch.setattr(ev, "INJECTED_FRACTIONS", (0.1,))
    rows = ev.evaluate_scan_types(shared_data)
    kinds = {r["kind"] for r in rows}
    assert kinds == {"clean", "injected", "bands"}
    methods = {r["method"] for r in rows if r["kind"] == "injected"}
    assert {"rpca", "rpca (no viewpoint)", "sor", "sor-oracle", "radius", "pcl-sor"} <= methods
    by = {(r["kind"], r["method"]): r for r in rows}
    assert by["clean", "rpca"]["flagged"] <= 0.01  # do no harm on the raw Kinect segment
    assert by["injected", "rpca"]["f1"] >= by["injected", "sor"]["f1"]
    assert by["injected", "sor-oracle"]["f1"] >= by["injected", "sor"]["f1"]
    assert by["bands", "rpca"]["recall_5_15"] >= 0.5
    text = "\n".join(ev.format_scan_types(rows))
    assert "| tuning | Kinect segment | injected 10 % | 1 |" in text
    assert "| tuning | Kinect segment | bands |" in text


def test_cli_outliers_viewpoint(tmp_path, capsys):
    from spectrageo import io, noise
    from spectrageo.cli.main import main
    from spectrageo.geometry import PointCloud

    rng = np.random.default_rng(3)
    P = np.column_stack([rng.uniform(-1, 1, (3000, 2)), np.full(3000, 2.0)])  # a wall at z = 2
    Q, lab = noise.add_outliers(P, fraction=0.05, kind="far", rng=1, shuffle=True)
    src, dst, mask = tmp_path / "in.ply", tmp_path / "out.ply", tmp_path / "keep.npy"
    io.write(src, PointCloud(Q))
    assert main(["outliers", str(src), str(dst), "--viewpoint", "0,0,0", "--mask", str(mask)]) == 0
    keep = np.load(mask)
    want = detect_outliers(Q, options=RPCAOptions(viewpoint=(0, 0, 0))).keep
    np.testing.assert_array_equal(keep, want)
    assert np.count_nonzero(~keep & lab) >= 0.9 * lab.sum()
    for extra, msg in (
        (["--viewpoint", "0,0"], "X,Y,Z"),
        (["--viewpoint", "a,b,c"], "X,Y,Z"),
        (["--viewpoint", "0,0,0", "--method", "sor"], "--method rpca only"),
        (["--viewpoint", "0,0,0", "--tile", "1000"], "not applied per tile"),
    ):
        capsys.readouterr()
        assert main(["outliers", str(src), str(tmp_path / "o2.ply"), *extra]) != 0
        assert msg in capsys.readouterr().err


def test_sparse_stage_adds_isolated_points_and_nothing_on_a_clean_surface():
    """The sparse-point stage (``sparse_factor``) on a clean sphere changes nothing; with
    injected far outliers it removes at least what the scores alone remove."""
    from spectrageo import noise

    rng = np.random.default_rng(5)
    P = rng.standard_normal((6000, 3))
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    on, off = detect_outliers(P), detect_outliers(P, options=RPCAOptions(sparse_factor=None))
    np.testing.assert_array_equal(on.keep, off.keep)
    assert on.info["n_sparse_outliers"] == 0
    Q, lab = noise.add_outliers(P, fraction=0.2, kind="near", distance=(5, 15), rng=2)
    on, off = detect_outliers(Q), detect_outliers(Q, options=RPCAOptions(sparse_factor=None))
    assert not np.any(~off.keep & on.keep)  # the stage only removes
    assert np.count_nonzero(~on.keep & lab) >= np.count_nonzero(~off.keep & lab)
    assert np.count_nonzero(~on.keep & ~lab) <= 0.01 * P.shape[0]
    with pytest.raises(InvalidInputError, match="sparse_factor"):
        RPCAOptions(sparse_factor=0)
