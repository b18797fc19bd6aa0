"""Feature vertices/curves, similarity, simplification, inspection, point clouds, animations,
saliency-aware denoising, CLI and evaluation of the saliency package (thesis Section 6.1)."""

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.stats import pearsonr

from spectrageo._errors import InvalidInputError
from spectrageo.saliency import (
    SaliencyOptions,
    animation_saliency,
    calinski_harabasz_1d,
    class_keep_fractions,
    curve_descriptor,
    curve_similarity,
    feature_curves,
    feature_vertices,
    first_ring_patches,
    inspect,
    kmeans_1d,
    multiscale_features,
    normalize_saliency_pair,
    pointcloud_saliency,
    saliency,
    saliency_denoise,
    saliency_patch_weights,
    select_patches_by_saliency,
    similarity_matrix,
    simplify,
    vertex_spectral_saliency,
)

from conftest import cube, grid, icosphere


def _rotation(seed=0):
    Q, R = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q if np.linalg.det(Q) > 0 else -Q


def _edge_distance(P):
    a = np.sort(1.0 - np.abs(P), axis=1)
    return np.hypot(a[:, 0], a[:, 1])


# --------------------------------------------------------------------------- clustering helpers
def test_kmeans_1d_separates_groups_and_orders_labels():
    rng = np.random.default_rng(0)
    x = np.r_[rng.normal(0, 0.01, 50), rng.normal(1, 0.01, 30), rng.normal(5, 0.01, 20)]
    lab, cen = kmeans_1d(x, 3)
    np.testing.assert_array_equal(lab, np.r_[np.zeros(50), np.ones(30), 2 * np.ones(20)])
    np.testing.assert_allclose(cen, [x[:50].mean(), x[50:80].mean(), x[80:].mean()])
    lab2, cen2 = kmeans_1d(np.array([1.0, 1.0, 2.0]), 5)  # fewer distinct values than clusters
    assert cen2.size == 2 and set(lab2) == {0, 1}


def test_calinski_harabasz_matches_sklearn():
    from sklearn.metrics import calinski_harabasz_score

    rng = np.random.default_rng(1)
    x = rng.normal(size=200)
    lab, _ = kmeans_1d(x, 4)
    assert calinski_harabasz_1d(x, lab) == pytest.approx(calinski_harabasz_score(x[:, None], lab))
    assert np.isnan(calinski_harabasz_1d(x, np.zeros(200)))


# --------------------------------------------------------------------------- features
def test_vertex_saliency_flat_is_zero_and_cube_corners_are_max():
    V, F = grid(10, 10)
    np.testing.assert_array_equal(vertex_spectral_saliency(V, F, patch=9), 0.0)
    V, F = cube(4)
    s = vertex_spectral_saliency(V, F, patch=15)
    corners = np.flatnonzero((np.abs(np.abs(V) - 1) < 1e-9).all(axis=1))
    assert len(corners) == 8
    assert s[corners].min() > np.quantile(s, 0.9)


def test_feature_vertices_on_cube():
    V, F = cube(4)
    fv = feature_vertices(V, F, patch=15)
    corners = (np.abs(np.abs(V) - 1) < 1e-9).all(axis=1)
    assert fv.mask[corners].all()
    far = _edge_distance(V) > 0.6
    assert far.any() and not fv.mask[far].any()
    assert set(np.unique(fv.classes)) <= set(range(5))
    np.testing.assert_array_equal(fv.mask, fv.classes >= 2)


def test_feature_vertices_constant_map_has_no_features():
    V, F = cube(3)
    fv = feature_vertices(V, saliency=np.full(len(V), 0.3))
    assert not fv.mask.any()


def test_feature_curves_labels_and_connected_split():
    V, F = cube(4)
    fc = feature_curves(V, F, patch=15)
    assert 1 <= fc.n_curves <= 5
    np.testing.assert_array_equal(fc.labels >= 0, fc.features.mask)
    assert set(fc.scores) <= {2, 3, 4, 5}
    fcc = feature_curves(V, F, patch=15, connected=True)
    np.testing.assert_array_equal(fcc.labels >= 0, fc.features.mask)
    assert fcc.n_curves >= fc.n_curves
    # each connected curve is connected along mesh edges
    from scipy.sparse.csgraph import connected_components

    from spectrageo.graph import adjacency_matrix

    A = adjacency_matrix(F, len(V)).tocsr()
    for c in range(fcc.n_curves):
        idx = np.flatnonzero(fcc.labels == c)
        n_comp, _ = connected_components(A[idx][:, idx], directed=False)
        assert n_comp == 1


def test_descriptor_and_similarity():
    rng = np.random.default_rng(0)
    s, m = rng.random(100), rng.normal(size=100)
    q = curve_descriptor(s, m)
    assert (
        q.shape == (20,) and q[:10].sum() == pytest.approx(1) and q[10:].sum() == pytest.approx(1)
    )
    assert curve_similarity(q, q) == pytest.approx(1.0)
    assert curve_similarity(q, 3 * q + 1) == pytest.approx(1.0)
    assert curve_similarity(q, np.ones(20)) == 0.0
    r = curve_similarity(q, curve_descriptor(rng.random(100) ** 3, rng.normal(size=100)))
    assert -1 <= r < 0.99


def test_similarity_matrix_of_models():
    V, F = cube(4)
    Vs, Fs = icosphere(3)
    S = similarity_matrix([(V, F), (2.0 * V @ _rotation(2).T + 1.0, F), (Vs, Fs)], patch=15)
    np.testing.assert_allclose(S, S.T)
    np.testing.assert_allclose(np.diag(S), 1.0)
    assert S[0, 1] > 0.95
    assert S[0, 1] > S[0, 2]


# --------------------------------------------------------------------------- simplification
def _check_valid(Vs, Fs):
    assert Fs.min() >= 0 and Fs.max() < len(Vs)
    assert (Fs[:, 0] != Fs[:, 1]).all() and (Fs[:, 1] != Fs[:, 2]).all()
    assert (Fs[:, 0] != Fs[:, 2]).all()
    assert len(np.unique(np.sort(Fs, axis=1), axis=0)) == len(Fs)
    assert len(np.unique(Fs)) == len(Vs)


def test_class_keep_fractions_meet_total():
    counts = np.array([500, 300, 150, 50])
    p = class_keep_fractions(counts, 400)
    assert (p * counts).sum() == pytest.approx(400, abs=1e-6)
    assert np.all(np.diff(p) >= 0) and p.max() <= 1
    np.testing.assert_allclose(class_keep_fractions(counts, 2000), 1.0)


def test_simplify_keeps_salient_vertices_and_gives_valid_mesh():
    V, F = cube(5)
    s = saliency(V, F, SaliencyOptions(k=15), method="spectral")
    res = simplify(V, F, ratio=0.8, saliency=s, n_classes=4, rng=0)
    _check_valid(res.vertices, res.faces)
    np.testing.assert_array_equal(res.vertices, V[res.kept])
    assert len(res.vertices) <= round(0.2 * len(V)) + 4
    assert np.all(np.diff(res.keep_fractions) >= 0)
    kept = np.zeros(len(V), bool)
    kept[res.kept] = True
    corners = (np.abs(np.abs(V) - 1) < 1e-9).all(axis=1)
    assert kept[corners].mean() > kept[~corners].mean()
    assert kept[res.classes == 3].mean() > kept[res.classes == 0].mean()
    # the simplified closed cube stays closed: every edge has two faces
    import trimesh

    assert trimesh.Trimesh(res.vertices, res.faces, process=False).is_watertight


def test_simplify_explicit_fractions_and_top():
    V, F = cube(4)
    s = np.linalg.norm(V, axis=1)
    res = simplify(V, F, saliency=s, n_classes=2, keep_fractions=[0.0, 1.0], within="top")
    cls = res.classes
    assert set(res.kept) <= set(np.flatnonzero(cls == 1))
    _check_valid(res.vertices, res.faces)


def test_simplify_validation():
    V, F = cube(3)
    with pytest.raises(InvalidInputError, match="`ratio` must be in"):
        simplify(V, F, ratio=1.0, saliency=np.zeros(len(V)))
    with pytest.raises(InvalidInputError, match="`keep_fractions` must be"):
        simplify(V, F, saliency=np.zeros(len(V)), keep_fractions=[2.0, 0, 0, 0])
    with pytest.raises(InvalidInputError, match="`saliency` must have shape"):
        simplify(V, F, saliency=np.zeros(3))
    with pytest.raises(InvalidInputError, match="given together with"):
        simplify(V, F, saliency=np.zeros(len(V)), method="spectral")
    with pytest.raises(InvalidInputError, match="`within` must be one of"):
        simplify(V, F, saliency=np.zeros(len(V)), within="x")
    with pytest.raises(InvalidInputError, match="`weights` must be"):
        simplify(V, F, saliency=np.zeros(len(V)), weights=[1, 2])
    with pytest.raises(InvalidInputError, match="fewer than 3"):
        simplify(V, F, saliency=np.zeros(len(V)), keep_fractions=[0.0, 0, 0, 0])


# --------------------------------------------------------------------------- inspection
def test_inspect_scaled_copy_is_clean_and_dent_is_found():
    V, F = cube(5)
    V = V + 0.002 * np.random.default_rng(1).standard_normal(V.shape)  # break kNN ties
    ins = inspect(V, F, 2.5 * V + 7.0, F, method="spectral", options=SaliencyOptions(k=15))
    np.testing.assert_allclose(ins.deviation, 0.0, atol=1e-9)
    np.testing.assert_allclose(ins.distance, 0.0, atol=1e-12)
    Vd = V.copy()
    centre = np.array([0.0, 0.0, 1.0])
    dent = np.linalg.norm(V - centre, axis=1) < 0.35
    Vd[dent, 2] -= 0.15 * (1 - np.linalg.norm(V[dent] - centre, axis=1) / 0.35)
    ins = inspect(V, F, 1.7 * Vd, F, method="spectral", options=SaliencyOptions(k=15))
    assert ins.heat[dent].mean() > 5 * ins.heat[~dent].mean()
    with pytest.raises(InvalidInputError, match="`saliency_ref` must have shape"):
        inspect(V, F, V, F, saliency_ref=np.zeros(2), saliency_copy=np.zeros(len(V)))
    with pytest.raises(InvalidInputError, match="`saliency_weight` must be"):
        inspect(V, F, V, F, saliency_weight=-1.0)


# --------------------------------------------------------------------------- point clouds
def test_pointcloud_saliency_edges_and_invariance():
    V, F = cube(5)
    V = V + 0.002 * np.random.default_rng(1).standard_normal(V.shape)  # break kNN ties
    s = pointcloud_saliency(V, k=20)
    d = _edge_distance(V)
    assert s[d < 0.1].mean() > s[d > 0.6].mean() + 0.3
    s2 = pointcloud_saliency(4.0 * V @ _rotation(3).T - 2.0, k=20)
    assert pearsonr(s, s2)[0] > 0.99
    P = grid(12, 12)[0]
    np.testing.assert_allclose(
        pointcloud_saliency(P, k=8, normals=np.tile([0, 0, 1.0], (144, 1))), 0
    )
    raw = pointcloud_saliency(V, k=20, normalize=False)
    assert raw.min() >= 1 / 21 - 1e-12 and raw.max() <= np.sqrt(3) / 21 + 1e-12


def test_multiscale_features_and_pair_normalisation():
    rng = np.random.default_rng(0)
    P = rng.random((300, 3))
    s = rng.random(300)
    f = multiscale_features(P, s, K=5, n_scales=5)
    assert f.shape == (300, 8)
    np.testing.assert_array_equal(f[:, :3], P)
    _, idx = cKDTree(P).query(P, k=15)
    np.testing.assert_allclose(f[:, 3], s[idx[:, :5]].mean(axis=1))
    np.testing.assert_allclose(f[:, 5], s[idx].mean(axis=1))
    a, b = normalize_saliency_pair(np.array([0.05, 0.06]), np.array([0.048, 0.07]), K_s=100)
    assert b[0] == 0.0 and (a > 0).all() and a[1] > a[0] and b.max() < 1
    with pytest.raises(InvalidInputError, match="`saliency` must have shape"):
        multiscale_features(P, s[:5])
    with pytest.raises(InvalidInputError, match="`normals` must have shape"):
        pointcloud_saliency(P, normals=np.zeros((2, 3)))


# --------------------------------------------------------------------------- animations
def test_animation_reuse_static_and_rigid_frames():
    V, F = cube(4)
    V = V + 0.01 * np.random.default_rng(0).standard_normal(V.shape)
    frames = np.stack([V, V, V @ _rotation(5).T])
    res = animation_saliency(frames, F, SaliencyOptions(k=12))
    np.testing.assert_allclose(res.values[0], saliency(V, F, SaliencyOptions(k=12)))
    assert res.recomputed[0].all() and not res.recomputed[1:].any()
    np.testing.assert_array_equal(res.values[1], res.values[0])
    # threshold 0 recomputes every vertex; a rigid motion leaves the map unchanged (Eq. 6.16)
    full = animation_saliency(frames, F, SaliencyOptions(k=12), threshold=0.0)
    assert full.recomputed.all()
    np.testing.assert_allclose(full.values[2], full.values[0], atol=1e-6)


def test_animation_recomputes_only_deformed_area():
    V, F = cube(4)
    W = V.copy()
    moved = V[:, 2] > 0.9
    W[moved, 2] += 0.3 * (1 - V[moved, 0] ** 2)  # bulge the top face
    res = animation_saliency(np.stack([V, W]), F, SaliencyOptions(k=12), method="spectral")
    rec = res.recomputed[1]
    assert rec.any() and rec.mean() < 0.5
    assert (V[rec, 2] > 0.5).all()
    np.testing.assert_array_equal(res.values[1, ~rec], res.values[0, ~rec])
    with pytest.raises(InvalidInputError, match="`frames` must have shape"):
        animation_saliency(V, F)


# --------------------------------------------------------------------------- denoising
def test_select_patches_by_saliency_matches_brute_force():
    V, F = icosphere(2)
    rng = np.random.default_rng(0)
    s = rng.random(len(F))
    P = first_ring_patches(F)
    best = select_patches_by_saliency(s, P)
    Pd = P.toarray() > 0
    xi = np.array([s[row].mean() for row in Pd])  # Eq. 6.21
    for i in range(len(F)):
        cands = np.flatnonzero(Pd[:, i])
        assert best[i] == cands[np.argmin(xi[cands])]  # Eq. 6.20
    W = saliency_patch_weights(V, F, s)
    np.testing.assert_allclose(np.asarray(W.sum(axis=1)).ravel(), 1.0)
    with pytest.raises(InvalidInputError, match="`face_saliency` must have shape"):
        select_patches_by_saliency(s[:3], P)


def test_saliency_denoise_reduces_normal_error():
    from spectrageo.metrics import theta_deg
    from spectrageo.noise import apply as add_noise

    V, F = cube(5)
    Vn = add_noise(V, F, kind="gaussian", level=0.2, rng=0)
    Vd = saliency_denoise(Vn, F, method="spectral", options=SaliencyOptions(k=15))
    t0 = theta_deg(Vn, V, F)
    t1 = theta_deg(Vd, V, F)
    assert t1 < 0.5 * t0
    with pytest.raises(InvalidInputError, match="`sigma_r` must be > 0"):
        saliency_denoise(Vn, F, sigma_r=0.0)


# --------------------------------------------------------------------------- CLI and evaluation
def _write_cube(tmp_path, name="cube.ply", subdiv=4, scale=1.0, jitter=True):
    from spectrageo import io
    from spectrageo.geometry import Mesh

    V, F = cube(subdiv)
    if jitter:  # break the kNN ties of the symmetric cube
        V = V + 0.002 * np.random.default_rng(1).standard_normal(V.shape)
    path = tmp_path / name
    io.write(path, Mesh(scale * V, F))
    return path, V, F


def test_cli_commands(tmp_path):
    from spectrageo import io
    from spectrageo.cli.main import main

    path, V, F = _write_cube(tmp_path, jitter=True)
    out = tmp_path / "s.npy"
    assert (
        main(["saliency", str(path), "--out", str(out), "--method", "spectral", "--k", "12"]) == 0
    )
    np.testing.assert_allclose(
        np.load(out), saliency(V, F, SaliencyOptions(k=12), method="spectral")
    )
    assert main(["saliency", str(path), "--out", str(tmp_path / "s.ply"), "--per", "face"]) == 0
    m = io.read(tmp_path / "s.ply")
    assert "saliency" in m.face_attributes and m.vertex_colors is not None
    assert main(["saliency", str(path), "--out", str(tmp_path / "s.csv")]) == 0
    assert np.loadtxt(tmp_path / "s.csv").shape == (len(V),)
    assert main(["features", str(path), "--out", str(tmp_path / "f.npy"), "--patch", "15"]) == 0
    lab = np.load(tmp_path / "f.npy")
    assert lab.shape == (len(F),) and set(np.unique(lab)) <= {0, 1, 2}
    assert main(["curves", str(path), "--out", str(tmp_path / "c.ply")]) == 0
    assert "curve" in io.read(tmp_path / "c.ply").vertex_attributes
    simp = tmp_path / "simp.ply"
    assert main(["simplify", str(path), str(simp), "--ratio", "0.7", "--method", "spectral"]) == 0
    ms = io.read(simp)
    _check_valid(ms.vertices, ms.faces)
    scaled, _, _ = _write_cube(tmp_path, "scaled.ply", scale=3.0)
    heat = tmp_path / "heat.ply"
    assert (
        main(["inspect", str(path), str(scaled), "--out", str(heat), "--method", "spectral"]) == 0
    )
    h = io.read(heat)
    np.testing.assert_allclose(h.vertex_attributes["deviation"], 0.0, atol=1e-9)
    assert main(["saliency", str(path), "--out", str(tmp_path / "s.txt")]) == 2
    assert main(["features", str(tmp_path / "missing.ply"), "--out", str(out)]) == 2


def test_cli_point_cloud_saliency(tmp_path):
    from spectrageo import io
    from spectrageo.cli.main import main
    from spectrageo.geometry import PointCloud

    V, _ = cube(4)
    io.write(tmp_path / "p.ply", PointCloud(V))
    assert (
        main(["saliency", str(tmp_path / "p.ply"), "--out", str(tmp_path / "p.npy"), "--k", "15"])
        == 0
    )
    np.testing.assert_allclose(np.load(tmp_path / "p.npy"), pointcloud_saliency(V, k=15))
    assert (
        main(
            ["saliency", str(tmp_path / "p.ply"), "--out", str(tmp_path / "q.npy"), "--per", "face"]
        )
        == 2
    )


def test_evaluate_on_synthetic_folder(tmp_path):
    from spectrageo import io
    from spectrageo.evaluate.saliency import evaluate, format_markdown
    from spectrageo.geometry import Mesh

    V0, F = cube(4)
    V = V0 + 0.01 * np.random.default_rng(0).standard_normal(V0.shape)
    io.write(tmp_path / "box.obj", Mesh(V, F))
    # analytic reference, independent of the saliency code: closeness of each face centroid to the
    # nearest edge of the cube [-1, 1]^3 (second largest |coordinate|, 1 on an edge)
    gt = np.sort(np.abs(V0[F].mean(axis=1)), axis=1)[:, 1]
    np.savetxt(tmp_path / "box_saliencyValues_of_centroids.csv", gt)
    rows = evaluate(
        tmp_path, methods=["spectral", "combined", "fast"], out=tmp_path / "ev", models=("box",)
    )
    by = {r["method"]: r for r in rows}
    # the harness correlates the map of the mesh it read with the reference file, face by face
    read = io.read_mesh(tmp_path / "box.obj")
    s_face = saliency(read.vertices, read.faces, method="spectral", per="face")
    assert by["spectral"]["pearson"] == pytest.approx(pearsonr(s_face, gt)[0], abs=1e-9)
    # and the spectral map does find the cube's edges
    assert by["spectral"]["pearson"] > 0.8 and by["spectral"]["spearman"] > 0.8
    assert by["spectral"]["invariance"] > 0.999
    assert by["fast"]["pearson_vs_combined"] > 0.9
    assert (tmp_path / "ev.md").read_text().startswith("| model")
    assert (tmp_path / "ev.csv").read_text().count("\n") == 4
    assert "box" in format_markdown(rows)
    with pytest.raises(InvalidInputError, match="`methods` must be among"):
        evaluate(tmp_path, methods=["nope"], models=("box",))
    with pytest.raises(InvalidInputError, match="missing"):
        evaluate(tmp_path, models=("other",))


def test_evaluate_real_data_spectral(shared_data):
    from spectrageo.evaluate.saliency import evaluate

    rows = evaluate(shared_data, methods=["spectral"], models=("fandisk",))
    assert rows[0]["pearson"] > 0.85 and rows[0]["spearman"] > 0.85
    assert rows[0]["invariance"] >= 0.99


def test_simplify_refuses_a_mesh_whose_faces_all_collapse():
    """A mesh of degenerate faces (every triangle repeats a vertex) left an empty mesh, which
    the CLI then failed to write with an unrelated message ("`vertices` is empty")."""
    V, F = grid(8, 8)
    Fd = np.c_[F[:, 0], F[:, 0], F[:, 1]]
    # refused before the saliency map (which has no surface to measure), one clear error
    with pytest.raises(InvalidInputError, match="every face of the mesh is degenerate"):
        simplify(V, Fd, ratio=0.5, method="geometric", options=SaliencyOptions(k=10), rng=0)


def test_inspect_refuses_a_copy_without_surface():
    """A scan whose vertices all coincide has no saliency; inspect used to map it to a constant
    deviation with exit status 0."""
    from spectrageo.saliency import inspect

    V, F = icosphere(2)
    with pytest.raises(InvalidInputError, match="V_copy"):
        inspect(V, F, np.zeros_like(V), F)
