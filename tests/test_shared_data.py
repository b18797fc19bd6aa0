"""Every file of the shared data folder reads, with the counts the data README gives.

Counts below were checked against the README (fandisk 6475 v, armadillo 26k -> 26002, dragon
437,645 / 100,250 / 22,998 v, crane 175 x 10002, horse-gallop 48 x 8431, horse-collapse 53 frames,
chickenCrossing 400 x 3030, fragment.pcd ~113k -> 113,662, autzen 110k -> 110,000, face000 85,849,
b9 22,300, parasaurolophus 6,700 / 28,291) and completed with the real counts of the other files.
Organized Kinect PCD frames (640 x 480) hold NaN for pixels without depth; they read with those
points dropped (PCD default), so the expected count is the number of valid points.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from spectrageo import InvalidInputError, io
from spectrageo.cli.main import main as cli
from spectrageo.datasets import denoise_pairs
from spectrageo.geometry import Mesh, MeshAnimation, PointCloud, PointCloudSequence

# Files that are not geometry (licences, notes, annotations, poses); skipped on purpose.
NON_GEOMETRY_SUFFIXES = {".csv", ".yml", ".txt", ".md", ".conf", ".log"}
NON_GEOMETRY_NAMES = {"README", "LICENSE_laspy", "LICENSE_abc-dataset-repo"}

# relative path -> (type, counts...): mesh (n_vertices, n_faces), points (n_points,),
# animation (n_frames, n_vertices, n_faces)
EXPECTED: dict[str, tuple] = {
    "animations/cat-poses.npz": ("animation", 9, 7207, 14410),
    "animations/chickenCrossing.npz": ("animation", 400, 3030, 5664),
    "animations/crane.npz": ("animation", 175, 10002, 20000),
    "animations/horse-collapse.npz": ("animation", 53, 8431, 16843),
    "animations/horse-gallop.npz": ("animation", 48, 8431, 16843),
    "animations/lion-poses.npz": ("animation", 9, 5000, 9996),
    # STL: welded on read (within 1e-6 of the diagonal); raw corner counts in STL_RAW
    "cad/abc_00000050.stl": ("mesh", 3795, 7614),
    "cad/angle_block.STL": ("mesh", 352, 704),
    "cad/featuretype.STL": ("mesh", 1722, 3476),
    "cad/octagonal_pocket.stl": ("mesh", 1631, 3262),
    "cad/plate_holes.STL": ("mesh", 618, 1252),
    "cad/cycloidal.ply": ("mesh", 21384, 43368),
    "cad/joint.obj": ("mesh", 20902, 41808),
    "cad/partLp.obj": ("mesh", 4261, 8530),
    "cad/screwdriver.obj": ("mesh", 27152, 54300),
    "denoise/Block0.4/Noisy.obj": ("mesh", 8771, 17550),
    "denoise/Block0.4/Original.obj": ("mesh", 8771, 17550),
    "denoise/BlockN1/Noisy.obj": ("mesh", 8771, 17550),
    "denoise/BlockN1/Original.obj": ("mesh", 8771, 17550),
    "denoise/Bunny0.2/Noisy.obj": ("mesh", 34834, 69451),
    "denoise/Bunny0.2/Original.obj": ("mesh", 34834, 69451),
    "denoise/Fandisk0.3/Noisy.obj": ("mesh", 6475, 12946),
    "denoise/Fandisk0.3/Original.obj": ("mesh", 6475, 12946),
    "denoise/Fandisk0.7/Noisy.obj": ("mesh", 6475, 12946),
    "denoise/Fandisk0.7/Original.obj": ("mesh", 6475, 12946),
    "denoise/SharpSphere0.3/Noisy.obj": ("mesh", 10443, 20882),
    "denoise/SharpSphere0.3/Original.obj": ("mesh", 10443, 20882),
    "denoise/TrimStar0.5/Noisy.obj": ("mesh", 5192, 10384),
    "denoise/TrimStar0.5/Original.obj": ("mesh", 5192, 10384),
    "denoise/Twelve0.5Impulsive/Noisy.obj": ("mesh", 4610, 9216),
    "denoise/Twelve0.5Impulsive/Original.obj": ("mesh", 4610, 9216),
    "denoise/real_scans/angel.obj": ("mesh", 24566, 48090),
    "denoise/real_scans/iron.ply": ("mesh", 85574, 168285),
    "denoise/real_scans/rabbit.obj": ("mesh", 37394, 73679),
    "holes/elephant-with-holes.off": ("mesh", 2798, 4463),
    "holes/elephant.off": ("mesh", 2775, 5558),
    "holes/holes.off": ("mesh", 4291, 8288),
    "holes/mech-holes-shark.off": ("mesh", 5246, 10192),
    "meshes/ChineseDragon-10kv.off": ("mesh", 10000, 19994),
    "meshes/anchor_dense.off": ("mesh", 3793, 7598),
    "meshes/armadillo.off": ("mesh", 26002, 52000),
    "meshes/bear.off": ("mesh", 13826, 27648),
    "meshes/blade.off": ("mesh", 8231, 16222),
    "meshes/bull.off": ("mesh", 6200, 12396),
    "meshes/camel.off": ("mesh", 9770, 19536),
    "meshes/cheese.off": ("mesh", 8629, 17786),
    "meshes/cow.off": ("mesh", 2904, 5804),
    "meshes/cube-meshed.off": ("mesh", 866, 1728),
    "meshes/dino.off": ("mesh", 3916, 7828),
    "meshes/diplodocus.off": ("mesh", 23982, 47960),
    "meshes/dragon_vrip.ply.gz": ("mesh", 437645, 871414),
    "meshes/dragon_vrip_res2.ply.gz": ("mesh", 100250, 202520),
    "meshes/dragon_vrip_res3.ply.gz": ("mesh", 22998, 47794),
    "meshes/elephant.off": ("mesh", 2775, 5558),
    "meshes/fandisk.off": ("mesh", 6475, 12946),
    "meshes/fandisk_large.off": ("mesh", 15843, 31682),
    "meshes/joint.off": ("mesh", 221, 446),
    "meshes/knot2.off": ("mesh", 5760, 11520),
    "meshes/lion.off": ("mesh", 7529, 14859),
    "meshes/man.off": ("mesh", 17495, 34986),
    "meshes/mushroom.off": ("mesh", 2337, 4608),
    "meshes/octahedron.off": ("mesh", 6, 8),
    "meshes/rocker-arm.obj": ("mesh", 10044, 20088),
    "meshes/rotor.off": ("mesh", 600, 1200),
    "meshes/spot.obj": ("mesh", 2930, 5856),
    "meshes/stanford-bunny.obj": ("mesh", 35947, 69451),
    "meshes/turbine.off": ("mesh", 9210, 18460),
    "saliency/block.obj": ("mesh", 8771, 17550),
    "saliency/block_gt_test.obj": ("mesh", 8771, 17550),
    "saliency/cad.obj": ("mesh", 19398, 38792),
    "saliency/cad_gt_test.obj": ("mesh", 19398, 38792),
    "saliency/casting.obj": ("mesh", 18410, 36852),
    "saliency/casting_gt_test.obj": ("mesh", 18410, 36852),
    "saliency/fandisk.obj": ("mesh", 6475, 12946),
    "saliency/fandisk_gt_test.obj": ("mesh", 6475, 12946),
    "scans/b9.ply": ("points", 22300),
    "scans/bunny/bun000.ply.gz": ("points", 40256),
    "scans/bunny/bun045.ply.gz": ("points", 40097),
    "scans/bunny/bun090.ply.gz": ("points", 30379),
    "scans/bunny/bun180.ply.gz": ("points", 40251),
    "scans/bunny/bun270.ply.gz": ("points", 31701),
    "scans/bunny/bun315.ply.gz": ("points", 35336),
    "scans/bunny/chin.ply.gz": ("points", 37738),
    "scans/bunny/ear_back.ply.gz": ("points", 32193),
    "scans/bunny/top2.ply.gz": ("points", 38298),
    "scans/bunny/top3.ply.gz": ("points", 36023),
    "scans/lidar/autzen_trim.laz": ("points", 110000),
    "scans/pcl/cturtle.pcd": ("points", 167198),
    "scans/pcl/grabber_sequence/frame_20121214T142255.814212.pcd": ("points", 307200 - 35625),
    "scans/pcl/grabber_sequence/frame_20121214T142256.068683.pcd": ("points", 307200 - 35805),
    "scans/pcl/grabber_sequence/frame_20121214T142256.332395.pcd": ("points", 307200 - 35872),
    "scans/pcl/milk.pcd": ("points", 13704),
    "scans/pcl/milk_cartoon_all_small_clorox.pcd": ("points", 307200 - 65793),
    "scans/pcl/milk_color.pcd": ("points", 13704),
    "scans/pcl/noisy_slice_displaced.pcd": ("points", 3782),
    "scans/pcl/office1.pcd": ("points", 307200 - 52744),
    "scans/pcl/table_scene_mug_stereo_textured.pcd": ("points", 307200 - 97920),
    "scans/rangemap/face000.ply": ("mesh", 85849, 166259),
    "scans/registration/open3d/cloud_bin_0.pcd": ("points", 3903),
    "scans/registration/open3d/cloud_bin_1.pcd": ("points", 3458),
    "scans/registration/open3d/fragment.pcd": ("points", 113662),
    "scans/registration/uwa/parasaurolophus_6700.ply": ("mesh", 6700, 9140),
    "scans/registration/uwa/parasaurolophus_low_normals2.ply": ("mesh", 28291, 54839),
}

# Not geometry: licences and notes, the ABC feature annotation (.yml), per-face saliency values
# (.csv), the bunny scan poses (bun.conf) and the Open3D registration initialisation (init.log).
SKIPPED = {
    "README.md",
    "cad/LICENSE_abc-dataset-repo",
    "cad/LICENSE_trimesh.md",
    "cad/abc_00000050_features.yml",
    "denoise/LICENSE_GuidedDenoising.txt",
    "meshes/COPYRIGHT_CGAL_data.txt",
    "saliency/README_source.md",
    "saliency/block_saliencyValues_of_centroids.csv",
    "saliency/cad_saliencyValues_of_centroids.csv",
    "saliency/casting_saliencyValues_of_centroids.csv",
    "saliency/fandisk_saliencyValues_of_centroids.csv",
    "scans/bunny/README",
    "scans/bunny/bun.conf",
    "scans/lidar/LICENSE_laspy",
    "scans/pcl/LICENSE.txt",
    "scans/rangemap/LICENSE_pymeshlab.txt",
    "scans/registration/open3d/LICENSE_Open3D.txt",
    "scans/registration/open3d/init.log",
}

# vertex counts of the STL parts: exact welding (bit-identical corners) leaves cracks where an
# exporter rounded the same corner differently; the default tolerance (1e-6 of the diagonal) closes
# them (featuretype: 288 vertices more with exact welding)
STL_WELDED = {
    "cad/abc_00000050.stl": (3795, 3795),
    "cad/angle_block.STL": (398, 352),
    "cad/featuretype.STL": (2010, 1722),
    "cad/octagonal_pocket.stl": (1658, 1631),
    "cad/plate_holes.STL": (618, 618),
}


def _is_geometry(path) -> bool:
    suffixes = [s.lower() for s in path.suffixes]
    return not (
        path.name in NON_GEOMETRY_NAMES or not suffixes or suffixes[-1] in NON_GEOMETRY_SUFFIXES
    )


def _discover(root) -> list[str]:
    return sorted(
        str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() and _is_geometry(p)
    )


# the files the table lists: each test needs shared_data (skipped, or failed under CI=true,
# without it), and test_table_matches_folder checks that the folder holds exactly these
FILES = sorted(EXPECTED)


def test_table_matches_folder(shared_data):
    """Every geometry file is in the table and every table entry exists (no stale counts)."""
    files = _discover(shared_data)
    assert files, "no geometry files found in the shared data folder"
    assert set(files) == set(EXPECTED)
    skipped = sorted(
        str(p.relative_to(shared_data))
        for p in shared_data.rglob("*")
        if p.is_file() and not _is_geometry(p)
    )
    # the skipped files are exactly the notes, licences, annotations and poses
    assert skipped == sorted(SKIPPED)


@pytest.mark.parametrize("rel", FILES)
def test_shared_file_reads_with_expected_counts(shared_data, rel, capsys):
    """Through ``spectrageo info --json`` (the user's path) and the Python reader."""
    assert cli(["info", str(shared_data / rel), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    obj = io.read(shared_data / rel)
    kind, *counts = EXPECTED[rel]
    if kind == "mesh":
        assert isinstance(obj, Mesh) and info["kind"] == "mesh"
        assert (obj.n_vertices, obj.n_faces) == tuple(counts)
        assert (info["n_vertices"], info["n_faces"], info["n_frames"]) == (*counts, 1)
        assert np.isfinite(obj.vertices).all()
        assert obj.faces.min() >= 0 and obj.faces.max() < obj.n_vertices
    elif kind == "points":
        assert isinstance(obj, PointCloud) and info["kind"] == "point_cloud"
        assert obj.n_points == counts[0] == info["n_vertices"]
        assert np.isfinite(obj.points).all()
    else:
        assert isinstance(obj, MeshAnimation) and info["kind"] == "animation"
        assert (obj.n_frames, obj.n_vertices, obj.n_faces) == tuple(counts)
        assert (info["n_frames"], info["n_vertices"], info["n_faces"]) == tuple(counts)
    assert np.all(np.isfinite(info["bbox"]))


@pytest.mark.parametrize("rel", sorted(STL_WELDED))
def test_stl_weld_counts(shared_data, rel):
    exact_count, welded_count = STL_WELDED[rel]
    raw = io.read_mesh(shared_data / rel, weld=False)
    assert raw.n_vertices == 3 * raw.n_faces
    exact = io.read_mesh(shared_data / rel, weld=True, weld_tol=0.0)
    assert exact.n_vertices == exact_count and exact.n_faces == raw.n_faces
    np.testing.assert_array_equal(exact.vertices[exact.faces], raw.vertices[raw.faces])
    welded, rep = io.read_with_report(shared_data / rel)
    assert welded.n_vertices == welded_count and welded.n_faces == raw.n_faces
    assert rep.n_merged_vertices == raw.n_vertices - welded_count
    # every corner moved by at most the tolerance
    diag = np.linalg.norm(np.ptp(raw.vertices, axis=0))
    moved = np.abs(welded.vertices[welded.faces] - raw.vertices[raw.faces]).max()
    assert moved <= 1e-6 * diag


def test_denoise_pairs_share_connectivity(shared_data):
    pairs = denoise_pairs(shared_data)
    assert len(pairs) == 8
    for name, noisy_path, orig_path in pairs:
        noisy, orig = io.read_mesh(noisy_path), io.read_mesh(orig_path)
        assert noisy.n_vertices == orig.n_vertices, name
        np.testing.assert_array_equal(noisy.faces, orig.faces, err_msg=name)
        # same vertex order: the noise moves vertices by a fraction of the model size
        d = np.linalg.norm(noisy.vertices - orig.vertices, axis=1)
        size = np.linalg.norm(np.ptp(orig.vertices, axis=0))
        assert 0 < d.mean() < 0.05 * size, name


def test_saliency_models_match_ground_truth_meshes(shared_data):
    for name in ("block", "cad", "casting", "fandisk"):
        mesh = io.read_mesh(shared_data / "saliency" / f"{name}.obj")
        gt = io.read_mesh(shared_data / "saliency" / f"{name}_gt_test.obj")
        np.testing.assert_array_equal(mesh.faces, gt.faces)
        values = np.loadtxt(
            shared_data / "saliency" / f"{name}_saliencyValues_of_centroids.csv", delimiter=","
        )
        assert len(values) == mesh.n_faces  # one saliency value per face centroid, face order kept


def test_grabber_sequence_folder(shared_data):
    seq = io.read(shared_data / "scans" / "pcl" / "grabber_sequence")
    assert isinstance(seq, PointCloudSequence)
    assert seq.n_points == [307200 - 35625, 307200 - 35805, 307200 - 35872]
    for frame in seq:
        assert frame.colors is not None and frame.colors.shape[1] == 4
        idx = frame.attributes["source_index"]
        assert idx.min() >= 0 and idx.max() < 640 * 480 and (np.diff(idx) > 0).all()


def test_organized_pcd_nan_count(shared_data):
    with pytest.raises(InvalidInputError, match="52744 of 307200 points have NaN"):
        io.read(shared_data / "scans" / "pcl" / "office1.pcd", nan_points="raise")


def test_pcd_fields_decoded(shared_data):
    frag = io.read(shared_data / "scans" / "registration" / "open3d" / "fragment.pcd")
    assert frag.normals is not None and "curvature" in frag.attributes
    np.testing.assert_allclose(np.linalg.norm(frag.normals, axis=1), 1.0, atol=1e-3)
    turtle = io.read(shared_data / "scans" / "pcl" / "cturtle.pcd")
    assert turtle.attributes["intensity"].shape == (167198,)
    milk = io.read(shared_data / "scans" / "pcl" / "milk_color.pcd")
    assert milk.colors.dtype == np.uint8 and milk.colors.shape == (13704, 4)


def test_autzen_las_fields(shared_data):
    pytest.importorskip("laspy")
    pytest.importorskip("lazrs")
    pc = io.read(shared_data / "scans" / "lidar" / "autzen_trim.laz")
    assert pc.colors.dtype == np.uint8 and pc.colors.shape == (110000, 3)
    assert {"intensity", "classification", "gps_time"} <= set(pc.attributes)


def test_ply_properties_decoded(shared_data):
    face = io.read_mesh(shared_data / "scans" / "rangemap" / "face000.ply")
    assert {"quality", "flags"} <= set(face.vertex_attributes)
    assert {"quality", "flags"} <= set(face.face_attributes)
    cyc = io.read_mesh(shared_data / "cad" / "cycloidal.ply")
    assert cyc.vertex_colors.shape == (21384, 4) and "red" in cyc.face_attributes
    para = io.read_mesh(shared_data / "scans" / "registration" / "uwa" / "parasaurolophus_6700.ply")
    assert para.vertex_normals is not None


def test_animation_npz_as_sequence(shared_data):
    seq = io.read_sequence(shared_data / "animations" / "lion-poses.npz")
    anim = io.read_animation(shared_data / "animations" / "lion-poses.npz")
    assert seq.n_points == [5000] * 9
    np.testing.assert_array_equal(seq.as_array(), anim.frames)


# ------------------------------------------------------------------ the user's path over every file
def _rows_and_attrs(obj):
    if isinstance(obj, Mesh):
        return (
            obj.n_vertices,
            obj.n_faces,
            obj.vertex_normals is not None,
            obj.vertex_colors is not None,
            sorted(obj.vertex_attributes),
            sorted(obj.face_attributes),
        )
    if isinstance(obj, PointCloud):
        return (
            obj.n_points,
            0,
            obj.normals is not None,
            obj.colors is not None,
            sorted(obj.attributes),
            [],
        )
    return (obj.n_frames, obj.n_vertices, obj.n_faces)


@pytest.mark.slow
@pytest.mark.parametrize("rel", FILES)
def test_shared_file_converts_without_loss(shared_data, rel, tmp_path, capsys):
    """``spectrageo convert`` to a lossless format keeps every row, face and attribute."""
    src = shared_data / rel
    obj = io.read(src)
    target = tmp_path / ("out.npz" if isinstance(obj, MeshAnimation) else "out.ply")
    assert cli(["convert", str(src), str(target), "--quiet"]) == 0, capsys.readouterr().err
    back = io.read(target)
    assert _rows_and_attrs(back) == _rows_and_attrs(obj)
    if isinstance(obj, Mesh):
        np.testing.assert_array_equal(back.vertices, obj.vertices)
        np.testing.assert_array_equal(back.faces, obj.faces)
    elif isinstance(obj, PointCloud):
        np.testing.assert_array_equal(back.points, obj.points)


SMALL_MESHES = [r for r in FILES if EXPECTED[r][0] == "mesh" and EXPECTED[r][1] <= 40_000]
# organized Kinect clouds: 640 x 480 rows, NaN where the sensor measured nothing
EXPECTED_ROWS = {
    r: 307200
    for r, v in EXPECTED.items()
    if r.startswith("scans/pcl/") and 200_000 < v[1] < 307_200
}
CLOUDS = [r for r in FILES if EXPECTED[r][0] == "points" and EXPECTED[r][1] <= 400_000]


@pytest.mark.slow
@pytest.mark.parametrize("rel", SMALL_MESHES)
def test_shared_mesh_denoises_through_cli(shared_data, rel, tmp_path, capsys):
    """Every shared mesh up to 40k vertices: the CLI's default denoiser runs, keeps the input's
    vertex count and faces and writes no NaN (meshes under 8 vertices get the fine step alone).
    How far it moves clean meshes is tested in test_denoise_clean.py."""
    src = shared_data / rel
    obj = io.read(src)
    out = tmp_path / "d.ply"
    code = cli(["denoise", str(src), str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 0, err
    d = io.read(out)
    assert d.n_vertices == obj.n_vertices
    np.testing.assert_array_equal(d.faces, obj.faces)
    assert np.isfinite(d.vertices).all()


@pytest.mark.slow
@pytest.mark.parametrize("rel", CLOUDS)
def test_shared_cloud_outliers_cover_every_row(shared_data, rel, tmp_path, capsys):
    """Outlier removal on every shared cloud: mask and scores have one entry per input row (NaN
    rows of organized PCDs included, never kept), no NaN score, and the written cloud has the
    kept rows."""
    src = shared_data / rel
    n_rows = EXPECTED_ROWS.get(rel, EXPECTED[rel][1])
    code = cli(
        [
            "outliers",
            str(src),
            str(tmp_path / "o.ply"),
            "--mask",
            str(tmp_path / "m.npy"),
            "--scores",
            str(tmp_path / "s.npy"),
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    mask, scores = np.load(tmp_path / "m.npy"), np.load(tmp_path / "s.npy")
    assert mask.shape == scores.shape == (n_rows,)
    assert not np.isnan(scores).any()
    assert io.read(tmp_path / "o.ply").n_points == int(mask.sum())
    n_finite = EXPECTED[rel][1]
    assert np.isinf(scores).sum() == n_rows - n_finite
    assert 0.5 * n_finite < mask.sum() < n_finite
