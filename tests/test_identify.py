"""Identification in cluttered scans (Section 6.2.3-6.2.8): adaptive DBSCAN, plane removal, the
scene generator, identify() and the ``spectrageo identify`` CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spectrageo._errors import InvalidInputError
from spectrageo.register import Match, Scene, adaptive_dbscan, identify, make_scene
from spectrageo.register._segment import adaptive_eps, remove_planes

from conftest import shared_file, skip_or_fail

# ------------------------------------------------------------------------------ segmentation


def _blobs(rng, n=400):
    """Three well-separated noisy sphere surfaces of different densities."""
    g = np.random.default_rng(rng)
    parts = []
    for c, m in (((0, 0, 0), n), ((5, 0, 0), 2 * n), ((0, 6, 1), n // 2)):
        d = g.normal(size=(m, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        parts.append(np.asarray(c) + d + 0.01 * g.normal(size=(m, 3)))
    truth = np.repeat(np.arange(3), [len(p) for p in parts])
    return np.concatenate(parts), truth


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_adaptive_dbscan_separates_and_agrees_with_sklearn(seed):
    from sklearn.cluster import DBSCAN
    from sklearn.metrics import adjusted_rand_score

    P, truth = _blobs(seed)
    lab = adaptive_dbscan(P)
    assert lab.shape == (P.shape[0],) and lab.dtype == np.int64
    assert set(np.unique(lab)) <= {-1, 0, 1, 2}
    assert (lab >= 0).mean() > 0.98
    ok = lab >= 0
    assert adjusted_rand_score(truth[ok], lab[ok]) == pytest.approx(1.0)
    # sizes decrease with the label (deterministic numbering)
    cnt = np.bincount(lab[ok])
    assert (np.diff(cnt) <= 0).all()
    eps = float(np.percentile(adaptive_eps(P), 90))
    sk = DBSCAN(eps=eps, min_samples=5).fit_predict(P)
    both = ok & (sk >= 0)
    assert both.mean() > 0.97
    assert adjusted_rand_score(sk[both], lab[both]) == pytest.approx(1.0)


def test_adaptive_eps_is_eq_6_29():
    P = np.c_[np.arange(10.0), np.zeros(10), np.zeros(10)]
    eps = adaptive_eps(P, k_a=2)
    # point 0: neighbours at 1 and 2 -> 2 * 1.5; point 5: at 1 and 1 -> 2 * 1
    assert eps[0] == pytest.approx(3.0) and eps[5] == pytest.approx(2.0)


def test_adaptive_dbscan_outliers_are_noise():
    P, _ = _blobs(3)
    far = np.array([[50.0, 50, 50], [-40, 30, 10], [20, -60, 0]])
    lab = adaptive_dbscan(np.r_[P, far], min_cluster_size=10)
    assert (lab[-3:] == -1).all()
    assert np.unique(lab[:-3][lab[:-3] >= 0]).size == 3


def test_remove_planes_keeps_objects():
    g = np.random.default_rng(0)
    plane = np.c_[g.uniform(-2, 2, (4000, 2)), 0.002 * g.normal(size=4000)]
    box = g.uniform(-0.3, 0.3, (800, 3)) + [0, 0, 0.5]
    keep, planes = remove_planes(np.r_[plane, box], threshold=0.02, rng=0)
    assert len(planes) >= 1 and abs(abs(planes[0][2]) - 1) < 1e-3
    assert keep[4000:].mean() > 0.95 and keep[:4000].mean() < 0.02


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"k_a": 0}, "`k_a` must be an integer >= 1"),
        ({"eps_scale": -1.0}, "`eps_scale` must be in"),
        ({"n_neighbors": 3, "k_a": 5}, "`n_neighbors` must be >= `k_a`"),
        ({"min_cluster_size": 0}, "`min_cluster_size` must be an integer"),
    ],
)
def test_adaptive_dbscan_validation(kwargs, match):
    P, _ = _blobs(0)
    with pytest.raises(InvalidInputError, match=match):
        adaptive_dbscan(P, **kwargs)


def test_adaptive_dbscan_bad_points():
    with pytest.raises(InvalidInputError, match="needs more than `k_a`"):
        adaptive_dbscan(np.zeros((4, 3)))
    with pytest.raises(InvalidInputError, match="must have shape"):
        adaptive_dbscan(np.zeros((10, 2)))


# ---------------------------------------------------------------------------- scene generator


def _primitives():
    import trimesh

    out = {}
    for name, m in (
        ("box", trimesh.creation.box(extents=(0.6, 0.4, 0.3))),
        ("cyl", trimesh.creation.cylinder(radius=0.2, height=0.6, sections=32)),
        ("cone", trimesh.creation.cone(radius=0.3, height=0.5, sections=32)),
    ):
        out[name] = (np.asarray(m.vertices, float), np.asarray(m.faces, np.int64))
    return out


def test_make_scene_ground_truth_is_consistent():
    from scipy.spatial import cKDTree

    from spectrageo.register.scenes import _sample_surface

    lib = _primitives()
    sc = make_scene(lib, n_objects=3, clutter=1, noise=0.0, image_size=(240, 180), rng=4)
    assert isinstance(sc, Scene) and sc.n_objects == 3
    assert sc.points.shape == (sc.labels.shape[0], 3)
    assert set(np.unique(sc.labels)) <= {-2, -1, 0, 1, 2}
    assert sorted(sc.names) == sorted(lib) and sc.model_index.tolist() == [0, 1, 2]
    # plane points lie on z = 0, all objects rest on or above it
    assert np.abs(sc.points[sc.labels == -1, 2]).max() < 1e-9
    assert sc.points[:, 2].min() > -1e-9
    for j, name in enumerate(sc.names):
        T = sc.poses[j]
        assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
        assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
        V, F = lib[name]
        surf = _sample_surface(V, F, 40000, np.random.default_rng(0)) @ T[:3, :3].T + T[:3, 3]
        pts = sc.points[sc.labels == j]
        assert pts.shape[0] > 50
        d, _ = cKDTree(surf).query(pts)
        assert np.percentile(d, 99) < 0.03  # on the posed model surface
        assert 0.0 < sc.visible_fraction[j] < 0.75  # one view: at least the back is hidden
    assert np.allclose(sc.occlusion, 1 - sc.visible_fraction)
    # deterministic for a seed
    sc2 = make_scene(lib, n_objects=3, clutter=1, noise=0.0, image_size=(240, 180), rng=4)
    assert np.array_equal(sc.points, sc2.points) and np.array_equal(sc.labels, sc2.labels)


def test_make_scene_noise_moves_points_along_rays():
    lib = _primitives()
    a = make_scene(lib, n_objects=2, clutter=0, noise=0.0, image_size=(160, 120), rng=1)
    b = make_scene(lib, n_objects=2, clutter=0, noise=0.5, image_size=(160, 120), rng=1)
    assert a.points.shape == b.points.shape
    d = b.points - a.points
    ray = a.points - a.viewpoint
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    cross = np.linalg.norm(np.cross(d, ray), axis=1)
    assert cross.max() < 1e-9 * max(1.0, np.abs(a.points).max())
    assert 0 < np.abs(d).max() < 5 * a.pixel_size


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_objects": 5}, r"`n_objects` must be in \[1, 3\]"),
        ({"occlusion": (0.9, 0.2)}, "`occlusion` must give"),
        ({"clutter": -1}, "`clutter` must be a non-negative integer"),
        ({"noise": float("nan")}, "`noise` must be a finite number"),
        ({"image_size": (8, 8)}, "`image_size` must lie in"),
    ],
)
def test_make_scene_validation(kwargs, match):
    with pytest.raises(InvalidInputError, match=match):
        make_scene(_primitives(), **{"n_objects": 2, **kwargs})


def test_make_scene_bad_models():
    with pytest.raises(InvalidInputError, match="`models` is empty"):
        make_scene([])
    with pytest.raises(InvalidInputError, match="must be a mesh path"):
        make_scene([np.zeros((10, 3))], n_objects=1)


# ----------------------------------------------------------------------------------- identify


def _library(shared):
    from spectrageo.evaluate.identify import LIBRARY, load_library

    lib = load_library(shared)
    names = ("bunny", "cow", "armadillo", "fandisk")
    if any(n not in lib for n in names):
        skip_or_fail(f"shared models missing: {[LIBRARY[n] for n in names if n not in lib]}")
    return {n: lib[n] for n in names}


@pytest.fixture(scope="module")
def small_case(shared_data):
    lib = _library(shared_data)
    scene_lib = {k: lib[k] for k in ("bunny", "cow")}
    sc = make_scene(scene_lib, n_objects=2, clutter=1, image_size=(480, 360), rng=3)
    res = identify(sc.points, lib, rng=0)
    return lib, sc, res


def test_identify_finds_present_and_rejects_absent(small_case):
    from spectrageo.metrics.registration import rotation_error_deg, translation_error

    lib, sc, res = small_case
    assert [m.model for m in res] == list(lib)
    for m in res:
        assert isinstance(m, Match)
        assert m.transformation.shape == (4, 4) and m.segment.dtype == np.int64
        assert m.n_points == m.segment.size
        present = m.model in sc.names
        assert m.found == present, (m.model, m.dissimilarity)
        assert (m.dissimilarity < 0.4) == present
        if present:
            j = sc.names.index(m.model)
            T, Tg = m.transformation, sc.poses[j]
            assert rotation_error_deg(T[:3, :3], Tg[:3, :3]) < 5.0
            assert translation_error(T[:3, 3], Tg[:3, 3]) < 0.02
            # the segment is mostly the object's points
            assert (sc.labels[m.segment] == j).mean() > 0.8


def test_identify_is_deterministic(small_case):
    """Same seed, same answer; a model's answer does not depend on the other models given."""
    lib, sc, res = small_case
    first = {m.model: m for m in res}
    again = identify(sc.points, {"fandisk": lib["fandisk"], "cow": lib["cow"]}, rng=0)
    for m in again:
        a = first[m.model]
        assert m.found == a.found and m.dissimilarity == a.dissimilarity
        assert np.array_equal(m.transformation, a.transformation)
        assert np.array_equal(m.segment, a.segment)
    other = identify(sc.points, {"cow": lib["cow"]}, rng=1)[0]
    assert other.found  # another seed still finds it


def test_identify_milk_in_pcl_scene(shared_data):
    from spectrageo import io
    from spectrageo.metrics.registration import rotation_error_deg, translation_error
    from spectrageo.register.scenes import random_rotation

    d = shared_file(shared_data, "scans", "pcl", "milk.pcd").parent
    S = io.read(d / "milk_cartoon_all_small_clorox.pcd").points
    M = io.read(d / "milk.pcd").points
    # the model was cut out of this scan; move it by a known motion so that the pose is real work
    R = random_rotation(np.random.default_rng(11))
    t = np.array([0.2, -0.3, 0.5])
    m = identify(S, {"milk": M @ R.T + t}, rng=0)[0]
    assert m.model == "milk" and m.found and m.dissimilarity < 0.4
    T = m.transformation
    assert rotation_error_deg(T[:3, :3], R.T) < 2.0
    assert translation_error(T[:3, 3], -R.T @ t) < 0.01
    # the segment is the carton: nearly every model point has a segment point nearby
    from scipy.spatial import cKDTree

    dd, _ = cKDTree(S[m.segment]).query(M[::20])
    assert np.median(dd) < 0.005


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"zeta": -1}, "`zeta` must be a positive number"),
        ({"k_p": 0}, "`k_p` must be a positive integer"),
        ({"tau": 1.5}, r"`tau` must be in \(0, 1\)"),
        ({"voxel": 0.0}, "`voxel` must be a positive number or None"),
        ({"bogus": 1}, "unknown option"),
    ],
)
def test_identify_option_validation(kwargs, match):
    P = np.random.default_rng(0).normal(size=(200, 3))
    with pytest.raises(InvalidInputError, match=match):
        identify(P, [P], **kwargs)


def test_identify_input_validation(tmp_path):
    P = np.random.default_rng(0).normal(size=(200, 3))
    with pytest.raises(InvalidInputError, match="`models` is empty"):
        identify(P, [])
    with pytest.raises(InvalidInputError, match="`models` must be a list or a dict"):
        identify(P, P)
    with pytest.raises(InvalidInputError, match="at least 50 points"):
        identify(P[:20], [P])
    with pytest.raises(InvalidInputError, match="at least 30 points"):
        identify(P, [P[:10]])
    with pytest.raises(InvalidInputError, match="NaN or inf"):
        identify(np.r_[P, [[np.nan, 0, 0]]], [P])
    with pytest.raises(InvalidInputError, match="file not found"):
        identify(str(tmp_path / "nope.ply"), [P])


def test_identify_absent_everything_on_noise():
    """A scene of random blobs matches no smooth model."""
    import trimesh

    g = np.random.default_rng(2)
    S = g.uniform(-1, 1, (3000, 3))
    m = trimesh.creation.torus(major_radius=0.5, minor_radius=0.15)
    res = identify(S, {"torus": (np.asarray(m.vertices), np.asarray(m.faces))}, rng=0)
    assert len(res) == 1 and not res[0].found and res[0].dissimilarity >= 0.4


# ---------------------------------------------------------------------------------------- CLI


def test_cli_identify_writes_report(tmp_path, shared_data):
    from spectrageo import io
    from spectrageo.cli.main import main
    from spectrageo.geometry import Mesh, PointCloud

    lib = _library(shared_data)
    sc = make_scene({"cow": lib["cow"]}, n_objects=1, clutter=1, image_size=(320, 240), rng=1)
    scene_p = tmp_path / "scene.ply"
    io.write(scene_p, PointCloud(sc.points))
    paths = []
    for name in ("cow", "fandisk"):
        p = tmp_path / f"{name}.off"
        io.write(p, Mesh(*lib[name]))
        paths.append(str(p))
    out = tmp_path / "report.json"
    vp = ",".join(repr(float(x)) for x in sc.viewpoint)
    rc = main(["identify", str(scene_p), *paths, "--out", str(out), "--viewpoint", vp])
    assert rc == 0
    rep = json.loads(out.read_text())
    assert "time_s" in rep and rep["time_s"] > 0
    assert rep["viewpoint"] == [float(x) for x in sc.viewpoint]
    assert [m["model"] for m in rep["matches"]] == paths
    for m in rep["matches"]:
        assert set(m) >= {
            "model",
            "found",
            "dissimilarity",
            "transformation",
            "n_points",
            "segment",
        }
        assert np.asarray(m["transformation"]).shape == (4, 4)
        assert len(m["segment"]) == m["n_points"]
    assert rep["matches"][0]["found"] and not rep["matches"][1]["found"]


def test_cli_identify_errors(tmp_path, capsys):
    from spectrageo.cli.main import main

    rc = main(
        ["identify", str(tmp_path / "missing.ply"), "m.off", "--out", str(tmp_path / "r.json")]
    )
    assert rc != 0
    err = capsys.readouterr().err
    assert "file not found" in err and "Traceback" not in err
    assert not (tmp_path / "r.json").exists()
    with pytest.raises(SystemExit) as exc:
        main(
            ["identify", "s.ply", "m.off", "--out", str(tmp_path / "r.json"), "--viewpoint", "1,2"]
        )
    assert exc.value.code == 2
    assert "X,Y,Z" in capsys.readouterr().err


def test_ransac_inlier_count_kernel_matches_numpy():
    """The compiled hypothesis scoring equals the dense numpy count."""
    from spectrageo.register._common import random_rotation
    from spectrageo.register._kernels import count_inliers

    g = np.random.default_rng(4)
    A = g.normal(size=(700, 3))
    B = A + 0.05 * g.normal(size=A.shape)
    R = np.stack([np.eye(3)] + [random_rotation(g) for _ in range(9)])
    t = np.concatenate([np.zeros((1, 3)), 0.1 * g.normal(size=(9, 3))])
    thr2 = 0.15**2
    ref = ((np.einsum("hij,nj->hni", R, A) + t[:, None] - B) ** 2).sum(axis=2) <= thr2
    N = g.normal(size=A.shape)
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    got = count_inliers(R, t, A, B, thr2, N, N, 0.0)  # no normal test
    np.testing.assert_array_equal(got, ref.sum(axis=1))
    assert got[0] > 600 and got[1:].max() < 100
    # with the normal test: the rotated model normal must agree with the segment normal
    NB = N.copy()
    NB[:350] = np.cross(N[:350], [0.0, 0.0, 1.0])  # orthogonal to the model normal
    NB[:350] /= np.linalg.norm(NB[:350], axis=1, keepdims=True)
    agree = np.abs(np.einsum("hij,nj,ni->hn", R, N, NB)) >= 0.8
    got_n = count_inliers(R, t, A, B, thr2, N, NB, 0.8)
    np.testing.assert_array_equal(got_n, (ref & agree).sum(axis=1))
    assert got_n[0] <= got[0] - 300


def test_guided_sampling_lists_are_the_compatible_pairs():
    """The compiled compatibility lists equal a dense numpy evaluation of the same rule."""
    from spectrageo.register._kernels import compatible_lists

    g = np.random.default_rng(7)
    A = g.normal(size=(300, 3))
    B = A + 0.02 * g.normal(size=A.shape)
    B[::3] = g.normal(size=(100, 3))  # a third of the correspondences wrong
    NA = g.normal(size=A.shape)
    NA /= np.linalg.norm(NA, axis=1, keepdims=True)
    NB = NA + 0.1 * g.normal(size=A.shape)
    NB /= np.linalg.norm(NB, axis=1, keepdims=True)
    anchors = g.choice(300, 40, replace=False).astype(np.int64)
    voxel, max_d, sep, cos_tol = 0.02, 2.5, 0.2, 0.25
    cnt, flat = compatible_lists(A, B, NA, NB, anchors, voxel, max_d, sep, cos_tol)
    dA = np.linalg.norm(A[None] - A[anchors][:, None], axis=2)
    dB = np.linalg.norm(B[None] - B[anchors][:, None], axis=2)
    ok = (np.abs(dA - dB) <= 0.1 * np.maximum(dA, dB) + voxel) & (dB <= max_d) & (dB >= sep)
    ok &= np.abs(np.abs(NA @ NA[anchors].T).T - np.abs(NB @ NB[anchors].T).T) <= cos_tol
    np.testing.assert_array_equal(cnt, ok.sum(axis=1))
    np.testing.assert_array_equal(flat, np.nonzero(ok)[1])
    # wrong correspondences are rarely compatible with a right anchor
    right = anchors % 3 != 0
    wrong_share = np.mean([np.mean(flat[o : o + c] % 3 == 0)
                           for o, c in zip(np.r_[0, np.cumsum(cnt)[:-1]][right], cnt[right])])  # fmt: skip
    assert wrong_share < 0.2
