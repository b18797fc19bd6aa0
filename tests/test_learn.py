"""Learned denoisers (issue 20): numpy inference, torch training, registry and CLI."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import scipy.sparse as sp

from spectrageo import denoise, metrics, noise
from spectrageo._errors import InvalidInputError
from spectrageo.cli.main import main
from spectrageo.datasets import denoise_pairs, fandisk
from spectrageo.learn import _features as fe
from spectrageo.learn import _nn
from spectrageo.learn._weights import DEFAULT_WEIGHTS, load_weights, save_weights, unrotate_unit
from spectrageo.learn.bm3d_cnn import bm3d_cnn
from spectrageo.learn.dae import FramesTrainOptions, dae, dae_animation, train_frames_model

from conftest import shared_file, skip_or_fail


@pytest.fixture(scope="module")
def noisy_fandisk():
    m = fandisk()
    Vn = noise.generate(m.vertices, m.faces, kind="gaussian-normal", level=0.3, rng=1).vertices
    return Vn, m.vertices, m.faces


def _images(V, F, n=600, channels=6, seed=0):
    N, idx, G, R = fe.mesh_inputs(V, F)
    sel = np.random.default_rng(seed).choice(F.shape[0], n, replace=False)
    img = fe.normal_images(G, idx, R, rows=5, faces=sel)
    if channels == 6:
        img = np.concatenate([img, fe.normal_images(N, idx, R, rows=5, faces=sel)], axis=1)
    return img, R[sel], sel


# --------------------------------------------------------------------------- features
def test_rotations_map_to_axis_and_are_orthogonal():
    g = np.random.default_rng(0).normal(size=(200, 3))
    g[0] = (-1.0, 0.0, 0.0)  # opposite to e_x
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    R = fe.rotations_to_axis(g)
    assert np.allclose(np.einsum("mij,mj->mi", R, g), [1.0, 0.0, 0.0], atol=1e-12)
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)


def test_image_layout_follows_fig_5_40():
    assert fe.column_order(9).tolist() == [4, 5, 3, 6, 2, 7, 1, 8, 0]
    C = np.c_[np.arange(12.0) ** 1.5, np.zeros(12), np.zeros(12)]  # distinct spacings on a line
    idx = fe.centroid_knn(C, 5)
    assert (idx[:, 0] == np.arange(12)).all()
    G = np.tile([1.0, 0.0, 0.0], (12, 1)) * np.arange(1, 13)[:, None]  # pixel value = face + 1
    img = fe.normal_images(G, idx, np.tile(np.eye(3), (12, 1, 1)), rows=2)
    row0 = img[6, 0, 0]  # first row of face 6: itself in the centre column
    assert row0[2] == 7 and row0[3] == idx[6, 1] + 1 and row0[1] == idx[6, 2] + 1
    assert img[6, 0, 1, 2] == idx[6, 1] + 1  # second row centred at the nearest centroid


def test_fast_paths_match_their_references(noisy_fandisk):
    """The copy-free image build, the indexed CNN kernel, the compiled row moments and the
    RPCA on the non-zero columns give what the straightforward code gives."""
    from spectrageo.denoise import _normals as nm
    from spectrageo.learn.dae import face_rows, feature_mask
    from spectrageo.linalg import rpca

    Vn, _, F = noisy_fandisk
    N, idx, G, R = fe.mesh_inputs(Vn, F)
    img, _ = fe.build_images(Vn, F, rows=5, channels=6)
    sep = np.concatenate([fe.normal_images(P, idx, R, rows=5) for P in (G, N)], axis=1)
    assert np.array_equal(img, sep)
    with pytest.raises(ValueError, match="cannot take"):
        fe.normal_images(G, idx, R, rows=5, out=np.empty((3, 6, 5, 9), np.float32))
    with pytest.raises(ValueError, match="cannot take"):
        fe.normal_images(G, idx, R, rows=5, out=img, channel=4)
    # eigenvalues of C = I^T I / k, float32 and float64 rows, against LAPACK
    first = img[:, :3, 0, :]
    ref = np.linalg.eigvalsh(np.einsum("bik,bjk->bij", first.astype(np.float64), first) / 9)
    assert np.abs(fe.row_eigenvalues(first) - ref).max() < 1e-12
    assert np.abs(fe.row_eigenvalues(first.astype(np.float64)) - ref).max() < 1e-12
    # the compiled guided pixels equal the generic guided normals on the kNN patches (Eq. 4.8-4.11)
    P = sp.csr_matrix((np.ones(idx.size), idx.ravel(), np.arange(0, idx.size + 1, 9)))
    g_ref = nm.guided_normals(N, np.ones(len(N)), nm.PatchSet.from_matrix(P), measure="thesis")
    assert np.array_equal(fe.guided_pixels(N, idx), g_ref)
    dup = idx.copy()
    dup[:, -1] = dup[:, -2]  # repeated members (padded rows) count once
    Pd = sp.csr_matrix((np.ones(dup.size), dup.ravel(), np.arange(0, dup.size + 1, 9)))
    g_dup = nm.guided_normals(N, np.ones(len(N)), nm.PatchSet.from_matrix(Pd), measure="thesis")
    assert np.array_equal(fe.guided_pixels(N, dup), g_dup)
    # Eq. (4.9)'s patch term
    Rm = np.asarray(P @ (N[:, :, None] * N[:, None, :]).reshape(-1, 9)).reshape(-1, 3, 3)
    lam = np.linalg.eigvalsh(Rm)
    assert np.abs(nm._thesis_patch_term(N, P) - np.abs(lam[:, 0] - lam[:, 1])).max() < 1e-12
    # the CNN on a subset, in place, equals the CNN on the copied subset (both paths)
    rng = np.random.default_rng(3)
    W1, b1 = rng.normal(0, 0.1, (8, 6, 5, 5)), rng.normal(0, 0.1, 8)
    rw, mu = rng.normal(0, 1, (8, 9)), np.linspace(-1, 1, 9)
    W2, b2 = rng.normal(0, 0.1, (3, 8, 5, 5)), rng.normal(0, 0.1, 3)
    sel = rng.choice(img.shape[0], 500, replace=False)
    table = _nn.RBFTable(rw, mu, 0.5)
    for tab in (None, table):
        a = _nn.cnn_centre(img, W1, b1, rw, mu, 0.5, W2, b2, table=tab, index=sel)
        b = _nn.cnn_centre(img[sel], W1, b1, rw, mu, 0.5, W2, b2, table=tab)
        assert a.shape == (500, 3) and np.array_equal(a, b)
    # feature identification: the zero columns left out do not change the decision
    rows = face_rows(Vn, F)[0]
    M = rows - np.tile([1.0, 0.0, 0.0], rows.shape[1] // 3)
    assert np.abs(M[:, :3]).max() < 1e-9 and np.abs(M[:, 3:]).max(axis=0).min() > 1e-3
    full = rpca(M, method="ialm", on_nonconvergence="ignore", max_iter=200)
    want = np.linalg.norm(full.sparse, axis=1) > np.linalg.norm(full.low_rank, axis=1) + 0.7
    got = feature_mask(rows)
    assert 0 < got.sum() < got.size and np.array_equal(got, want)


def test_bm3d_cnn_chunks_do_not_change_the_result(noisy_fandisk):
    from spectrageo.learn import BM3DCNNModel

    Vn, _, F = noisy_fandisk
    model = BM3DCNNModel.load()
    whole = model.filter_normals(Vn, F, 0)
    assert np.array_equal(model.filter_normals(Vn, F, 0, chunk=997), whole)
    img, R = model.images(Vn, F)
    assert np.allclose(whole, unrotate_unit(R, model.predict(img, 0)), atol=1e-12)


def _grid_sheet(nx, z, offset=0):
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(nx, dtype=float))
    V = np.c_[x.ravel(), y.ravel(), np.full(nx * nx, z)]
    q = np.arange(nx * nx).reshape(nx, nx)[:-1, :-1].ravel()
    F = np.r_[np.c_[q, q + 1, q + nx], np.c_[q + 1, q + nx + 1, q + nx]] + offset
    return V, F


def test_face_neighbourhoods_stay_on_their_own_sheet():
    # two parallel sheets 0.2 apart, sampled every 1.0: the Euclidean nearest centroids of a
    # face lie on the other sheet, those within its vertex rings do not
    V1, F1 = _grid_sheet(8, 0.0)
    V2, F2 = _grid_sheet(8, 0.2, offset=64)
    V, F = np.r_[V1, V2], np.r_[F1, F2]
    C = fe.face_centroids(V, F)
    sheet = np.r_[np.zeros(len(F1), int), np.ones(len(F2), int)]
    eu = fe.centroid_knn(C, 9)
    ring = fe.centroid_knn(C, 9, F)
    assert (sheet[eu] != sheet[:, None]).any(axis=1).mean() > 0.9
    assert (sheet[ring] == sheet[:, None]).all()
    assert (ring[:, 0] == np.arange(len(F))).all()
    d = np.linalg.norm(C[ring] - C[:, None], axis=2)
    assert (np.diff(d, axis=1) >= -1e-12).all()  # nearest first
    # on one sheet the rings hold the Euclidean neighbours (compared by distance: ties may pick
    # other faces), except at the two sharp corners, whose ninth is three rings away
    C1 = fe.face_centroids(V1, F1)
    one, eu1 = fe.centroid_knn(C1, 9, F1), fe.centroid_knn(C1, 9)
    d_ring = np.linalg.norm(C1[one] - C1[:, None], axis=2)
    d_eu = np.linalg.norm(C1[eu1] - C1[:, None], axis=2)
    assert np.isclose(d_ring, d_eu).all(axis=1).sum() == len(F1) - 2
    # a double fan whose two apices have 400 faces each: hundreds of candidates per face
    ang = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    Vf = np.r_[[[0, 0, 1.0]], np.c_[np.cos(ang), np.sin(ang), np.zeros(400)], [[0, 0, 0.0]]]
    rim = 1 + np.arange(400)
    Ff = np.r_[np.c_[np.zeros(400, int), rim, 1 + (rim % 400)],
               np.c_[np.full(400, 401), 1 + (rim % 400), rim]]  # fmt: skip
    Cf = fe.face_centroids(Vf, Ff)
    fan = fe.centroid_knn(Cf, 9, Ff)
    df = np.linalg.norm(Cf[fan] - Cf[:, None], axis=2)
    assert (fan[:, 0] == np.arange(800)).all() and (np.diff(df, axis=1) >= -1e-12).all()
    assert np.allclose(df, np.linalg.norm(Cf[fe.centroid_knn(Cf, 9)] - Cf[:, None], axis=2))
    # a piece with fewer faces than k repeats its farthest face
    tri = fe.centroid_knn(np.array([[0.0, 0, 0], [1, 0, 0]]), 4, np.array([[0, 1, 2], [1, 3, 2]]))
    assert tri.tolist() == [[0, 1, 1, 1], [1, 0, 0, 0]]


# --------------------------------------------------------------------------- numpy vs torch
def test_numpy_cnn_matches_torch(noisy_fandisk):
    torch = pytest.importorskip("torch")
    from spectrageo.learn import _torch as tt

    tt.setup(3)
    net = tt.ShrinkageCNN(3, 6, 8, 5).double()
    with torch.no_grad():  # non-trivial second layer and biases
        net.W2.normal_(0, 0.1)
        net.b1.normal_(0, 0.1)
        net.b2.normal_(0, 0.1)
    Vn, _, F = noisy_fandisk
    img, _, _ = _images(Vn, F, 300)
    cls = np.random.default_rng(0).integers(0, 3, img.shape[0])
    with torch.no_grad():
        ref = net(torch.tensor(img, dtype=torch.float64), torch.tensor(cls)).numpy()
    w = net.export()
    out = np.empty_like(ref)
    for c in range(3):
        s = cls == c
        out[s] = _nn.cnn_centre(
            img[s], w["W1"][c], w["b1"][c], w["rw"][c], w["mu"], net.s, w["W2"][c], w["b2"][c],
            chunk=64,
        )  # fmt: skip
    assert np.abs(out - ref).max() < 1e-5
    assert np.abs(out - img[:, :3, 0, 4]).max() > 1e-3  # the network does change the pixel
    # the fast path used at denoising time: tabulated RBFs, float32
    fast = np.empty_like(ref)
    for c in range(3):
        s = cls == c
        table = _nn.RBFTable(w["rw"][c], w["mu"], net.s)
        fast[s] = _nn.cnn_centre(
            img[s], w["W1"][c], w["b1"][c], w["rw"][c], w["mu"], net.s, w["W2"][c], w["b2"][c],
            table=table,
        )  # fmt: skip
    assert np.abs(fast - ref).max() < 1e-5


def test_numpy_dae_matches_torch():
    torch = pytest.importorskip("torch")
    from spectrageo.learn import _torch as tt

    tt.setup(4)
    net = tt.ContentDAE(4, 27, 16).double()
    X = np.random.default_rng(1).normal(size=(200, 27))
    g = np.random.default_rng(2).integers(0, 4, 200)
    with torch.no_grad():
        ref = net(torch.tensor(X), torch.tensor(g)).numpy()
    w = net.export()
    out = np.stack(
        [
            _nn.mlp_forward(X[i : i + 1], w["W1"][j], w["b1"][j], w["W2"][j], w["b2"][j])[0]
            for i, j in enumerate(g)
        ]
    )
    assert np.abs(out - ref).max() < 1e-5


# --------------------------------------------------------------------------- training
def test_training_a_few_steps_lowers_the_loss(noisy_fandisk):
    pytest.importorskip("torch")
    from spectrageo.geometry import face_normals
    from spectrageo.learn import _torch as tt

    Vn, V0, F = noisy_fandisk
    img, R, sel = _images(Vn, F, 1500)
    Y = np.einsum("mij,mj->mi", R, face_normals(V0, F)[sel]).astype(np.float32)
    cls = fe.assign_classes(
        fe.row_eigenvalues(img[:, :3, 0]), fe.kmeans(fe.row_eigenvalues(img[:, :3, 0]), 3)
    )
    dev = tt.setup(0, threads=1)
    net = tt.ShrinkageCNN(3, 6, 8, 5)
    before = tt.evaluate_loss(net, img, cls, Y, device=dev)
    hist = tt.fit(net, img, cls, Y, epochs=3, device=dev, batch_size=128, lr=3e-3)
    after = tt.evaluate_loss(net, img, cls, Y, device=dev)
    assert after < 0.9 * before
    assert hist["train"][-1] < hist["train"][0]


def test_numpy_mlp_training_lowers_loss():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(2000, 6))
    Y = np.tanh(X @ rng.normal(size=(6, 6)))
    _, losses = _nn.train_mlp_numpy(X, Y, hidden=16, epochs=5, rng=0)
    assert losses[-1] < 0.5 * losses[0]


def test_training_is_deterministic_for_a_seed(noisy_fandisk):
    pytest.importorskip("torch")
    from spectrageo.learn import _torch as tt

    Vn, _, F = noisy_fandisk
    img, _, _ = _images(Vn, F, 300)
    Y = np.zeros((300, 3), dtype=np.float32)
    Y[:, 0] = 1.0
    cls = np.zeros(300, dtype=np.int64)
    outs = []
    for _ in range(2):
        dev = tt.setup(7, threads=1)
        net = tt.ShrinkageCNN(3, 6, 4, 5)
        tt.fit(net, img, cls, Y, epochs=1, device=dev, batch_size=64, seed=7)
        outs.append(net.export()["W1"])
    assert np.array_equal(outs[0], outs[1])


# --------------------------------------------------------------------------- weights files
def test_weights_roundtrip_and_model_check(tmp_path):
    p = save_weights(tmp_path / "w.npz", {"a": np.arange(3.0)}, {"model": "dae", "seed": 1})
    arrays, meta = load_weights(p, "dae")
    assert meta["seed"] == 1 and meta["format_version"] == 1 and arrays["a"].tolist() == [0, 1, 2]
    with pytest.raises(InvalidInputError, match="holds a 'dae' model; expected 'bm3d-cnn'"):
        load_weights(p, "bm3d-cnn")
    with pytest.raises(InvalidInputError, match="not found"):
        load_weights(tmp_path / "missing.npz")
    np.savez(tmp_path / "plain.npz", a=np.zeros(2))
    with pytest.raises(InvalidInputError, match="no metadata"):
        load_weights(tmp_path / "plain.npz")
    q = save_weights(tmp_path / "b.npz", {"W1": np.zeros(2)}, {"model": "bm3d-cnn"})
    with pytest.raises(InvalidInputError, match="bm3d-cnn weights lack arrays: class_centres"):
        bm3d_cnn(*fandisk_small(), weights=q)
    with pytest.raises(InvalidInputError, match="dae weights lack arrays: centres"):
        dae(*fandisk_small(), weights=p)


def fandisk_small():
    m = fandisk()
    F = m.faces[:400]
    used, inv = np.unique(F, return_inverse=True)
    return m.vertices[used], inv.reshape(F.shape)


def test_shipped_weights_metadata():
    total = sum(p.stat().st_size for p in DEFAULT_WEIGHTS.values())
    assert total < 20 * 2**20
    for name, p in DEFAULT_WEIGHTS.items():
        _, meta = load_weights(p, name)
        for key in (
            "architecture",
            "training_meshes",
            "noise_levels",
            "seed",
            "epochs",
            "spectrageo_version",
        ):
            assert key in meta, (name, key)
        from spectrageo.learn.train import check_training_meshes

        check_training_meshes(meta["training_meshes"])  # none is a validation / benchmark shape


def test_shipped_weights_run_without_torch(tmp_path):
    code = textwrap.dedent(
        """
        import sys

        class _NoTorch:  # any import of torch now fails, as without the package
            def find_spec(self, name, path=None, target=None):
                if name == "torch" or name.startswith("torch."):
                    raise ImportError("torch is blocked in this test")

        sys.meta_path.insert(0, _NoTorch())
        import numpy as np
        from spectrageo import denoise, metrics, noise
        from spectrageo.datasets import fandisk
        m = fandisk()
        Vn = noise.generate(m.vertices, m.faces, kind="gaussian-normal", level=0.3, rng=2).vertices
        out = {}
        for method in ("bm3d-cnn", "dae"):
            X = denoise.denoise(Vn, m.faces, method=method)
            out[method] = metrics.theta_deg(X, m.vertices, m.faces)
        out["noisy"] = metrics.theta_deg(Vn, m.vertices, m.faces)
        assert "torch" not in sys.modules
        print(out)
        """
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    out = eval(res.stdout.strip().splitlines()[-1])  # noqa: S307 - our own dict literal
    assert out["bm3d-cnn"] < 0.6 * out["noisy"] and out["dae"] < 0.6 * out["noisy"]


# --------------------------------------------------------------------------- denoising
def test_bm3d_cnn_lowers_theta_on_a_shared_pair(shared_data):
    from spectrageo import io

    pair = {p[0]: p for p in denoise_pairs(shared_data)}.get("Fandisk0.3")
    if pair is None:
        skip_or_fail(f"pair Fandisk0.3 not in the shared data folder {shared_data}")
    n, o = io.read_mesh(pair[1]), io.read_mesh(pair[2])
    X = denoise.denoise(n.vertices, o.faces, method="bm3d-cnn")
    th_noisy = metrics.theta_deg(n.vertices, o.vertices, o.faces)
    th = metrics.theta_deg(X, o.vertices, o.faces)
    assert th < 0.5 * th_noisy


def test_dae_trained_on_first_frames_lowers_error(shared_data):
    path = shared_file(shared_data, "animations", "horse-gallop.npz")
    z = np.load(path)
    A = z["vertices"][:7].astype(np.float64)
    F = z["faces"].astype(np.int64)
    An = noise.animation_noise(A, F, kind="gaussian", level=0.3, rng=0)
    D = denoise.denoise_animation(An, F, method="dae", train_frames=5, temporal=1, epochs=4)
    assert D.shape == A.shape
    th_noisy = np.mean([metrics.theta_deg(An[t], A[t], F) for t in range(len(A))])
    th = np.mean([metrics.theta_deg(D[t], A[t], F) for t in range(len(A))])
    assert th < 0.7 * th_noisy


def test_dae_animation_validation(noisy_fandisk):
    Vn, _, F = noisy_fandisk
    A = np.stack([Vn, Vn])
    with pytest.raises(InvalidInputError, match="`train_frames` must be <= the number of frames"):
        train_frames_model(A, F, train_frames=5)
    with pytest.raises(InvalidInputError, match="`train_frames` must be >= 7 without clean"):
        train_frames_model(A, F, train_frames=2)
    with pytest.raises(InvalidInputError, match="`train_frames` must be >= 3 without clean"):
        train_frames_model(A, F, FramesTrainOptions(temporal=0), train_frames=2)
    with pytest.raises(InvalidInputError, match="`clean` must hold at least 2 frames"):
        train_frames_model(A, F, train_frames=2, clean=A[:1])
    with pytest.raises(InvalidInputError, match="either `train_frames` or `weights`"):
        dae_animation(A, F, train_frames=2, weights="w.npz")
    with pytest.raises(InvalidInputError, match="`n_stages` must be > 0"):
        dae_animation(A, F, train_frames=2, n_stages=0)


def test_training_options_validate_once_and_old_keywords_warn(noisy_fandisk):
    from spectrageo.learn import BM3DCNNTrainOptions, DAETrainOptions

    Vn, _, F = noisy_fandisk
    A = np.stack([Vn, Vn])
    with pytest.warns(DeprecationWarning, match="FramesTrainOptions"):
        with pytest.raises(InvalidInputError, match="`train_frames` must be >= 3 without clean"):
            train_frames_model(A, F, train_frames=2, temporal=0)
    with pytest.raises(TypeError, match="unexpected keyword argument 'tempral'"):
        train_frames_model(A, F, train_frames=2, tempral=0)
    with pytest.raises(InvalidInputError, match="`channels` must be 3, 6 or 9"):
        BM3DCNNTrainOptions(channels=4)
    with pytest.raises(InvalidInputError, match="`epochs` must be > 0"):
        DAETrainOptions(epochs=0)
    with pytest.raises(InvalidInputError, match="validation or benchmark shape"):
        DAETrainOptions(meshes=["denoise/Block0.4/Noisy.obj"])
    o = BM3DCNNTrainOptions(levels=[0.3])
    assert (o.epochs, o.per_case, o.levels) == (4, 2500, (0.3,))
    assert DAETrainOptions().meshes == DAETrainOptions(meshes=list(o.meshes)).meshes


def test_local_rotations_recover_a_turn_and_auto_motion_follows_the_poses(noisy_fandisk):
    from scipy.spatial.transform import Rotation

    from spectrageo.learn.dae import local_rotations, rotation_angles

    Vn, V0, F = noisy_fandisk
    Rt = Rotation.from_euler("xyz", [70, -20, 35], degrees=True).as_matrix()
    C = fe.face_centroids(V0, F)
    idx = fe.centroid_knn(C, 30, F)
    Q = local_rotations(C @ Rt.T + 3.0, C, idx)  # maps the turned copy back
    assert np.allclose(Q, Rt.T, atol=1e-9)
    assert np.allclose(rotation_angles(Q), np.degrees(np.arccos((np.trace(Rt) - 1) / 2)))
    with pytest.raises(InvalidInputError, match="`motion` must be one of"):
        FramesTrainOptions(motion="affine")
    # a pose set (the whole shape turned by 90 degrees from frame to frame) is compensated, a
    # still one is not; the model records the choice
    rng = np.random.default_rng(0)
    turn = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    poses = np.stack([V0 @ np.linalg.matrix_power(turn, t).T for t in range(8)])
    poses += rng.normal(0, 0.002, poses.shape)
    still = np.stack([V0] * 8) + rng.normal(0, 0.002, poses.shape)
    kw = {"train_frames": 8, "options": FramesTrainOptions(epochs=1, max_rows=3000)}
    assert train_frames_model(poses, F, **kw)[0].meta["motion"] == "rigid"
    assert train_frames_model(still, F, **kw)[0].meta["motion"] == "none"
    rigid = FramesTrainOptions(motion="rigid", epochs=1, max_rows=3000)
    assert train_frames_model(still, F, rigid, train_frames=8)[0].meta["motion"] == "rigid"
    # one clean training frame: no motion to measure
    one = {"train_frames": 1, "clean": still[:1], "options": kw["options"]}
    assert train_frames_model(still, F, **one)[0].meta["motion"] == "none"


def test_denoiser_option_validation(tmp_path):
    V, F = fandisk_small()
    with pytest.raises(InvalidInputError, match="`weights` file not found"):
        bm3d_cnn(V, F, weights=tmp_path / "nope.npz")
    with pytest.raises(InvalidInputError, match="`weights` file not found"):
        dae(V, F, weights=tmp_path / "nope.npz")


def test_iteration_options_are_checked():
    V, F = fandisk_small()
    with pytest.raises(InvalidInputError, match="`n_iter` must be > 0"):
        bm3d_cnn(V, F, n_iter=0)
    with pytest.raises(InvalidInputError, match="`vertex_iter` must be an integer"):
        dae(V, F, vertex_iter=2.5)


def test_training_meshes_must_be_held_out():
    from spectrageo.learn.train import check_training_meshes

    with pytest.raises(InvalidInputError, match="validation or benchmark shape"):
        check_training_meshes(["meshes/armadillo.off"])
    with pytest.raises(InvalidInputError, match="validation or benchmark shape"):
        check_training_meshes(["denoise/Fandisk0.3/Original.obj"])
    with pytest.raises(InvalidInputError, match="validation or benchmark shape"):
        check_training_meshes(["meshes/fandisk.off"])  # the shape of a benchmark pair


# --------------------------------------------------------------------------- registry and CLI
def test_registered():
    names = denoise.available()
    assert "bm3d-cnn" in names and "dae" in names
    assert "5.1.4" in denoise.get("bm3d-cnn").reference
    assert "5.1.3" in denoise.get("dae").reference


def test_cli_denoise_mesh_and_animation(tmp_path, noisy_fandisk):
    from spectrageo import io
    from spectrageo.geometry import Mesh, MeshAnimation

    Vn, V0, F = noisy_fandisk
    io.write(tmp_path / "n.ply", Mesh(Vn, F))
    assert main(["denoise", str(tmp_path / "n.ply"), str(tmp_path / "o.ply"), "--method", "bm3d-cnn",
                 "--weights", str(DEFAULT_WEIGHTS["bm3d-cnn"])]) == 0  # fmt: skip
    X = io.read_mesh(tmp_path / "o.ply").vertices
    assert metrics.theta_deg(X, V0, F) < metrics.theta_deg(Vn, V0, F)
    V, Fs = fandisk_small()
    frames = np.stack([V + 0.002 * np.random.default_rng(t).normal(size=V.shape) for t in range(8)])
    io.write(tmp_path / "a.npz", MeshAnimation(frames, Fs))
    assert main(["denoise", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--method", "dae",
                 "--train-frames", "7"]) == 0  # fmt: skip
    B = io.read(tmp_path / "b.npz").frames
    assert B.shape == frames.shape
    # --motion reaches the DAE: on this still animation auto chooses no compensation
    assert main(["denoise", str(tmp_path / "a.npz"), str(tmp_path / "c.npz"), "--method", "dae",
                 "--train-frames", "7", "--motion", "none"]) == 0  # fmt: skip
    assert np.array_equal(io.read(tmp_path / "c.npz").frames, B)
    assert main(["denoise", str(tmp_path / "a.npz"), str(tmp_path / "d.npz"), "--method", "dae",
                 "--train-frames", "7", "--motion", "rigid"]) == 0  # fmt: skip
    assert not np.array_equal(io.read(tmp_path / "d.npz").frames, B)


def test_cli_errors(tmp_path, capsys):
    from spectrageo import io
    from spectrageo.geometry import Mesh

    V, F = fandisk_small()
    io.write(tmp_path / "n.ply", Mesh(V, F))
    assert main(["denoise", str(tmp_path / "n.ply"), str(tmp_path / "o.ply"), "--method", "tsgsp",
                 "--weights", "w.npz"]) != 0  # fmt: skip
    assert "--weights applies to the learned methods" in capsys.readouterr().err
    assert main(["denoise", str(tmp_path / "n.ply"), str(tmp_path / "o.ply"), "--method", "dae",
                 "--train-frames", "3"]) != 0  # fmt: skip
    assert "--train-frames applies to animations" in capsys.readouterr().err
    assert main(["denoise", str(tmp_path / "n.ply"), str(tmp_path / "o.ply"), "--method", "dae",
                 "--motion", "rigid"]) != 0  # fmt: skip
    assert "--motion applies to --method dae with --train-frames" in capsys.readouterr().err
    assert main(["train", "dae", "--data", str(tmp_path / "nope"), "--out", "w.npz"]) != 0
    err = capsys.readouterr().err
    assert "--data must be a folder" in err or "install spectrageo[learn]" in err
    assert main(["train", "dae", "--data", str(tmp_path), "--out", str(tmp_path / "w.txt")]) != 0
    err = capsys.readouterr().err
    assert "--out must end in .npz" in err or "install spectrageo[learn]" in err


def test_cli_train_without_torch_says_how_to_install(tmp_path, capsys, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda n, *a: None if n == "torch" else real(n, *a)
    )
    assert main(["train", "dae", "--data", str(tmp_path), "--out", str(tmp_path / "w.npz")]) != 0
    assert "install spectrageo[learn]" in capsys.readouterr().err


def test_cli_train_tiny(tmp_path, capsys):
    pytest.importorskip("torch")
    from spectrageo import io
    from spectrageo.geometry import Mesh

    V, F = fandisk_small()
    (tmp_path / "data" / "meshes").mkdir(parents=True)
    io.write(tmp_path / "data" / "meshes" / "piece.ply", Mesh(V, F))
    out = tmp_path / "w.npz"
    code = main(["train", "bm3d-cnn", "--data", str(tmp_path / "data"), "--out", str(out), "--epochs", "1",
                 "--stages", "1", "--threads", "1", "--meshes", "meshes/piece.ply"])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    _, meta = load_weights(out, "bm3d-cnn")
    assert meta["training_meshes"] == ["meshes/piece.ply"] and meta["epochs"] == 1
    rep = json.loads(out.with_suffix(".json").read_text())
    assert rep["loss"][0]["train"] and out.with_suffix(".md").is_file()
    X = bm3d_cnn(V, F, weights=out)
    assert np.isfinite(X).all() and X.shape == V.shape


def test_training_start_replaces_the_noisy_inputs(tmp_path):
    """``start`` (benchmarks/learned_refine.py) is applied to every noisy training input before
    stage 1 and recorded in the metadata; a start that returns the clean mesh leaves the network
    a residual target of (almost) nothing, so its loss is far below that of noisy inputs."""
    pytest.importorskip("torch")
    from spectrageo import io
    from spectrageo.geometry import Mesh
    from spectrageo.learn.train import BM3DCNNTrainOptions, train_bm3d_cnn

    V, F = fandisk_small()
    (tmp_path / "meshes").mkdir()
    io.write(tmp_path / "meshes" / "piece.ply", Mesh(V, F))
    seen = []

    def clean(Vn, Fn):
        seen.append(float(np.abs(Vn - V).max()))
        return V

    kw = dict(meshes=["meshes/piece.ply"], levels=[0.3], epochs=1, n_stages=1, threads=1,
              report=False, per_case=500)  # fmt: skip
    opts = BM3DCNNTrainOptions(start=clean, **kw)
    a = train_bm3d_cnn(tmp_path, tmp_path / "a.npz", opts, log=None)
    b = train_bm3d_cnn(tmp_path, tmp_path / "b.npz", BM3DCNNTrainOptions(**kw), log=None)
    assert len(seen) == 1 and seen[0] > 0  # called once per case, on the noisy input
    assert a["meta"]["start"] == "clean" and "start" not in b["meta"]
    assert a["loss"][0]["train"][-1] < 0.5 * b["loss"][0]["train"][-1]


def test_time_ratios_compare_each_case_with_tsgsp_in_the_size_range():
    from spectrageo.learn.evaluate import format_markdown, time_ratios, versus_tsgsp

    def row(case, method, n, t):
        return {"part": "pairs", "case": case, "method": method, "n_vertices": n,
                "input_theta": 30.0, "theta_deg": 5.0, "time_s": t}  # fmt: skip

    rows = [row("a", "tsgsp", 20_000, 1.0), row("a", "bm3d-cnn", 20_000, 1.5),
            row("a", "dae", 20_000, 0.5), row("b", "tsgsp", 5_000, 1.0),
            row("b", "bm3d-cnn", 5_000, 9.0), row("c", "tsgsp", 50_000, 2.0),
            row("c", "bm3d-cnn", 50_000, 1.0), row("c", "bnf", 50_000, 1.0)]  # fmt: skip
    r = time_ratios(rows)
    assert r == {"bm3d-cnn": [1.5, 0.5], "dae": [0.5]}  # case b is below 10k vertices
    protocol = [dict(x, part="protocol") for x in rows]
    assert time_ratios(protocol) == {}  # timed once per case there: not for the speed target
    v = versus_tsgsp(rows + [row("c", "dae", 50_000, 1.0) | {"theta_deg": 40.0}])
    assert v[("pairs", "bm3d-cnn")] == {"cases": 3, "below_tsgsp": 0, "above_input": 0}
    assert v[("pairs", "dae")] == {"cases": 2, "below_tsgsp": 0, "above_input": 1}
    assert "`bm3d-cnn` median 1.00, largest 1.50 (2 cases)" in format_markdown(rows)
