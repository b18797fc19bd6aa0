"""`spectrageo metrics` between geometry that does not correspond: meshes of different resolution,
point clouds, a mesh and a point cloud; per-vertex metrics only with vertex correspondence."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spectrageo import Mesh, MeshAnimation, PointCloud, io, metrics
from spectrageo.cli.main import main

from conftest import icosphere

PER_VERTEX = ("theta_deg", "dmean", "dmax", "dist_n", "dmean_n", "nmsve")
SURFACE = (
    "hd_mean",
    "hd_max",
    "chamfer",
    "fscore",
    "precision",
    "recall",
    "fscore_radius",
    "n_points_result",
    "n_points_reference",
)


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def files(tmp_path):
    rng = np.random.default_rng(0)
    V, F = icosphere(2)
    W, G = icosphere(4)
    P = rng.normal(size=(400, 3))
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    Q = icosphere(3)[0]  # 642 points at least ~0.1 apart
    paths = {
        "coarse": tmp_path / "coarse.ply",
        "fine": tmp_path / "fine.obj",
        "cloud": tmp_path / "cloud.ply",
        "grid": tmp_path / "grid.pcd",
        "grid_moved": tmp_path / "grid_moved.xyz",
        "anim": tmp_path / "anim.npz",
    }
    io.write(paths["coarse"], Mesh(V, F))
    io.write(paths["fine"], Mesh(W, G))
    io.write(paths["cloud"], PointCloud(P))
    io.write(paths["grid"], PointCloud(Q))
    io.write(paths["grid_moved"], PointCloud(Q + [0.006, 0.0, -0.008]))
    io.write(paths["anim"], MeshAnimation(np.stack([V, 1.1 * V]), F))
    return paths


def _surface_only(d):
    assert d["correspondence"] is False and d["correspondence_reason"]
    for k in PER_VERTEX:
        assert k not in d, k
    for k in SURFACE:
        assert k in d and np.isfinite(d[k]), k


def test_meshes_of_different_resolution(capsys, files):
    code, out, err = run(capsys, "metrics", files["fine"], files["coarse"], "--json")
    assert code == 0, err
    d = json.loads(out)
    _surface_only(d)
    assert "no vertex correspondence" in err and "vertices" in d["correspondence_reason"]
    assert d["chamfer"] < 0.02 and d["fscore"] > 0
    ref = metrics.compare_surfaces(io.read_mesh(files["fine"]), io.read_mesh(files["coarse"]))
    assert d["hd_max"] == pytest.approx(ref["hd_max"], rel=1e-6)  # OBJ/PLY round the coordinates
    assert d["n_points_result"] == ref["n_points_result"]
    V, F = icosphere(2)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert d["fscore_radius"] == pytest.approx(0.01 * diag, rel=1e-6)
    # --radius overrides the default; a generous one captures everything
    code, out, _ = run(
        capsys, "metrics", files["fine"], files["coarse"], "--json", "--radius", "0.1"
    )
    d = json.loads(out)
    assert code == 0 and d["fscore_radius"] == 0.1 and d["fscore"] == 1.0
    # the text output says so too
    code, out, _ = run(capsys, "metrics", files["fine"], files["coarse"])
    assert code == 0 and "correspondence" in out and "chamfer" in out


def test_two_point_clouds(capsys, files):
    code, out, err = run(capsys, "metrics", files["grid_moved"], files["grid"], "--json")
    assert code == 0, err
    d = json.loads(out)
    _surface_only(d)
    # translated by 0.01, far below the spacing: every nearest neighbour is the moved point
    assert d["chamfer"] == pytest.approx(0.01, rel=1e-4) and d["hd_max"] == pytest.approx(
        0.01, rel=1e-4
    )
    assert d["n_points_result"] == d["n_points_reference"] == 642
    assert d["fscore"] == 1.0  # default radius: 1% of the diagonal 2 * sqrt(3) > 0.01
    code, out, _ = run(
        capsys, "metrics", files["grid_moved"], files["grid"], "--json", "--radius", "0.005"
    )
    assert code == 0 and json.loads(out)["fscore"] == 0.0


def test_mesh_against_point_cloud_both_ways(capsys, files):
    code, out, err = run(capsys, "metrics", files["fine"], files["cloud"], "--json")
    assert code == 0, err
    a = json.loads(out)
    _surface_only(a)
    code, out, err = run(
        capsys, "metrics", files["cloud"], files["fine"], "--json", "--radius", "0.05"
    )
    assert code == 0, err
    b = json.loads(out)
    _surface_only(b)
    # cloud points lie on the unit sphere, within the sagitta of the fine mesh surface
    assert b["hd_max_to_reference"] < 0.01 and b["n_points_result"] == 400
    assert a["hd_max"] == pytest.approx(b["hd_max"]) and a["chamfer"] == pytest.approx(b["chamfer"])


def test_corresponding_meshes_keep_every_key(capsys, files, tmp_path):
    V, F = icosphere(2)
    W = V + np.random.default_rng(1).normal(scale=0.01, size=V.shape)
    io.write(tmp_path / "noisy.ply", Mesh(W, F))
    code, out, err = run(capsys, "metrics", tmp_path / "noisy.ply", files["coarse"], "--json")
    assert code == 0, err
    d = json.loads(out)
    assert list(d)[: len(metrics.METRIC_KEYS)] == list(metrics.METRIC_KEYS)
    assert d["correspondence"] is True and "correspondence_reason" not in d
    assert d["hd_max"] <= d["dmax"] + 1e-12 and err == ""


def test_same_count_different_faces_is_not_correspondence(capsys, files, tmp_path):
    V, F = icosphere(2)
    io.write(tmp_path / "flip.ply", Mesh(V, F[:, [0, 2, 1]]))
    code, out, err = run(capsys, "metrics", tmp_path / "flip.ply", files["coarse"], "--json")
    assert code == 0, err
    d = json.loads(out)
    _surface_only(d)
    assert d["correspondence_reason"] == "different faces" and d["hd_max"] < 1e-6


def test_animation_against_mesh_is_an_error(capsys, files):
    code, out, err = run(capsys, "metrics", files["anim"], files["coarse"])
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "MeshAnimation and Mesh" in lines[0] and "Traceback" not in err


def test_animation_pair_still_works_and_rejects_radius(capsys, files):
    code, out, err = run(capsys, "metrics", files["anim"], files["anim"], "--json")
    assert code == 0, err
    assert json.loads(out)["hd_max"] < 1e-12
    code, _, err = run(capsys, "metrics", files["anim"], files["anim"], "--radius", "0.1")
    assert code == 2 and "radius" in err


def test_bad_radius_is_one_line(capsys, files):
    code, _, err = run(capsys, "metrics", files["fine"], files["coarse"], "--radius", "-1")
    assert code == 2 and "radius" in err and len(err.strip().splitlines()) == 1


def test_distances_across_thirty_orders_of_magnitude():
    """A mesh 1e38 times larger than the reference: the closest-point formulas' edge and area
    terms round to zero against the distance (they used to divide by zero); the union of the
    edges gives the answer instead."""
    V, F = icosphere(2)
    d = metrics.point_to_surface(V * 1e38, V, F).distances
    assert np.isfinite(d).all()
    np.testing.assert_allclose(d, 1e38, rtol=0.01)  # every vertex of the unit icosphere: |v| = 1
    r = metrics.compare_surfaces(Mesh(V * 1e38, F), Mesh(V, F))
    assert abs(r["hd_max"] / 1e38 - 1.0) < 0.01
