"""Mesh-animation denoising: Algorithm 3 (gft-rpca), RPCA on normals, per-frame baselines,
the evaluation harness and the known spatial-mask limitation (Section 5.1.2)."""

from __future__ import annotations

import dataclasses
import tracemalloc

import numpy as np
import pytest

from spectrageo import noise
from spectrageo._errors import InvalidInputError
from spectrageo.denoise import denoise, denoise_animation, dynamic_methods
from spectrageo.denoise import dynamic as dyn
from spectrageo.geometry import MeshAnimation
from spectrageo.graph import adjacency_matrix, laplacian_from_adjacency
from spectrageo.metrics import theta_per_frame

from conftest import grid, icosphere


def bumpy_animation(T: int = 30, subdivisions: int = 3):
    """A bumpy sphere that stretches, twists, rotates and translates over ``T`` frames."""
    V, F = icosphere(subdivisions)
    r = 1 + 0.15 * np.sin(4 * V[:, 0]) * np.cos(3 * V[:, 1]) + 0.1 * np.sign(V[:, 2]) * V[:, 2] ** 2
    V = V * r[:, None]
    out = []
    for t in range(T):
        s = np.sin(2 * np.pi * t / T)
        a = 0.6 * s
        R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        W = V @ np.diag([1 + 0.25 * s, 1.0, 1 - 0.15 * s])
        tw = 0.4 * s * W[:, 2]
        c, si = np.cos(tw), np.sin(tw)
        W = np.c_[c * W[:, 0] - si * W[:, 1], si * W[:, 0] + c * W[:, 1], W[:, 2]]
        out.append(W @ R.T + np.array([0.1 * t, 0.0, 0.0]))
    return np.stack(out), F


def waving_grid(T: int = 12, n: int = 14, seed: int = 0):
    """A waving height-field sheet with randomly flipped diagonals (no symmetric spectrum)."""
    V, F = grid(n, n)
    rng = np.random.default_rng(seed)
    flip = rng.random(F.shape[0] // 2) < 0.5
    half = F.shape[0] // 2
    a, b, c = F[:half, 0], F[:half, 1], F[:half, 2]
    d = F[half:, 2]
    F1 = np.where(flip[:, None], np.c_[a, b, d], np.c_[a, b, c])
    F2 = np.where(flip[:, None], np.c_[b, c, d], np.c_[a, c, d])
    F = np.r_[F1, F2]
    x, y = V[:, 0], V[:, 1]
    frames = [
        np.c_[x, y, 0.2 * np.sin(3 * x + 0.4 * t) * np.cos(2 * y) + 0.03 * np.sin(17 * x * y)]
        for t in range(T)
    ]
    return np.stack(frames), F


def mean_theta(X, A, F) -> float:
    return float(np.mean(theta_per_frame(X, A, F)))


@pytest.fixture(scope="module")
def anim():
    return bumpy_animation()


# --------------------------------------------------------------------------- API
def test_dynamic_methods_listed():
    assert dynamic_methods() == ["gft-rpca", "normals-rpca"]


def test_energy_one_is_identity_exact_and_partitioned():
    A, F = waving_grid()
    for basis, kw in (("exact", {}), ("partitioned", {"submesh_size": 60})):
        res = dyn.gft_rpca(A, F, options=dyn.GFTRPCAOptions(energy=1.0, basis=basis, **kw))
        assert np.abs(res.frames - A).max() < 1e-10
        assert (res.n_high == 0).all()
    # several overlapped submeshes were used and reassembled without changing anything
    assert res.n_submeshes > 2


def test_identical_frames_are_kept():
    """A static animation makes every coherent matrix rank one: the low-rank estimate is exact."""
    A, F = waving_grid(T=8)
    A = np.repeat(A[:1], 8, axis=0)
    out = dyn.gft_rpca(A, F, options=dyn.GFTRPCAOptions(basis="exact")).frames
    assert np.abs(out - A).max() < 1e-8


def _reference_algorithm3(A, F, energy, rank):
    """Independent implementation of Algorithm 3 with a pure rank-r truncation (no sparse part)."""
    n = A.shape[1]
    C = adjacency_matrix(F, n)
    C.data[:] = 1.0
    _, U = np.linalg.eigh(laplacian_from_adjacency(C).toarray())
    out = np.empty_like(A)
    H = np.stack([U.T @ A[t] for t in range(A.shape[0])])  # (T, n, 3)
    E_s = (H**2).sum(axis=(1, 2))
    nh_i = np.zeros(A.shape[0], dtype=int)
    for t in range(A.shape[0]):
        e = (H[t] ** 2).sum(axis=1)[::-1]  # highest frequency first
        c = 0.0
        for e_j in e:
            if c + e_j > (1 - energy) * E_s[t]:
                break
            c += e_j
            nh_i[t] += 1
    nh = nh_i.max()
    Hd = H.copy()
    for c in range(3):
        M = H[:, n - nh :, c]
        u, s, vt = np.linalg.svd(M, full_matrices=False)
        E = (u[:, :rank] * s[:rank]) @ vt[:rank]
        for t in range(A.shape[0]):
            if nh_i[t]:
                Hd[t, n - nh_i[t] :, c] = E[t, nh - nh_i[t] :]
    for t in range(A.shape[0]):
        out[t] = U @ Hd[t]
    return out, nh


def test_exact_basis_matches_independent_reference():
    A, F = waving_grid(T=10, n=12)
    An = noise.animation_noise(A, F, kind="gaussian", level=0.3, rng=3)
    ref, nh = _reference_algorithm3(An, F, energy=0.999, rank=2)
    # a huge threshold switches the sparse part off: GoDec reduces to the rank-2 truncation
    opts = dyn.GFTRPCAOptions(
        basis="exact", energy=0.999, rank=2, lam=1e12, max_iter=2000, tol=1e-14
    )
    res = dyn.gft_rpca(An, F, options=opts)
    assert res.n_high[0, 0] == nh > 0
    assert np.abs(res.frames - ref).max() < 1e-7 * np.abs(A).max()


def test_partitioned_with_one_submesh_equals_exact():
    A, F = waving_grid(T=10, n=12)
    An = noise.animation_noise(A, F, kind="gaussian", level=0.3, rng=4)
    kw = dict(energy=0.999, rank=2, lam=1e12, max_iter=2000, tol=1e-14)
    ex = dyn.gft_rpca(An, F, options=dyn.GFTRPCAOptions(basis="exact", **kw))
    pa = dyn.gft_rpca(
        An, F, options=dyn.GFTRPCAOptions(basis="partitioned", submesh_size=500, **kw)
    )
    assert pa.n_submeshes == 1
    assert np.abs(pa.frames - ex.frames).max() < 1e-7 * np.abs(A).max()


def test_block_mode_equals_separate_runs():
    A, F = waving_grid(T=12, n=12)
    An = noise.animation_noise(A, F, kind="gaussian", level=0.3, rng=5)
    kw = dict(basis="exact", rank=2, lam=1e12, max_iter=2000, tol=1e-14)
    whole = dyn.gft_rpca(An, F, options=dyn.GFTRPCAOptions(**kw))
    same = dyn.gft_rpca(An, F, block_size=12, options=dyn.GFTRPCAOptions(**kw))
    assert np.abs(whole.frames - same.frames).max() < 1e-9
    blocks = dyn.gft_rpca(An, F, block_size=5, options=dyn.GFTRPCAOptions(**kw))
    assert blocks.n_high.shape == (1, 3)
    sep = np.concatenate(
        [
            dyn.gft_rpca(An[s : s + 5], F, options=dyn.GFTRPCAOptions(**kw)).frames
            for s in (0, 5, 10)
        ]
    )
    assert np.abs(blocks.frames - sep).max() < 1e-7 * np.abs(A).max()


def test_input_not_modified_and_meshanimation_accepted(anim):
    A, F = anim
    An = noise.animation_noise(A[:10], F, kind="gaussian", level=0.1, rng=0)
    keep = An.copy()
    out = denoise_animation(MeshAnimation(An, F), method="gft-rpca")
    assert out.shape == An.shape
    np.testing.assert_array_equal(An, keep)


# --------------------------------------------------------------------------- quality
def test_gaussian_noise_removed_and_beats_per_frame_bnf(anim):
    A, F = anim
    An = noise.animation_noise(A, F, kind="gaussian", level=0.1, rng=1)
    noisy = mean_theta(An, A, F)
    res = dyn.gft_rpca(An, F)
    got = mean_theta(res.frames, A, F)
    assert got < 0.5 * noisy
    sub = slice(0, 30, 3)  # per-frame BNF on every third frame keeps the test short
    bnf = mean_theta(dyn.denoise_frames(An[sub], F, method="bnf"), A[sub], F)
    assert mean_theta(res.frames[sub], A[sub], F) < bnf
    # the exact basis gives nearly the same result on a single-submesh mesh
    ex = mean_theta(dyn.gft_rpca(An, F, options=dyn.GFTRPCAOptions(basis="exact")).frames, A, F)
    assert abs(ex - got) < 0.1 * got


def test_spatial_mask_limitation(anim):
    """Fig. 5.29: noise repeated identically in every frame is low rank and survives Algorithm 3,
    while independent noise of the same level is mostly removed."""
    A, F = anim
    gauss = noise.animation_noise(A, F, kind="gaussian", level=0.1, rng=1)
    mask = noise.spatial_mask(A, F, fraction=0.5, level=0.1, rng=1).vertices
    ratio_gauss = mean_theta(dyn.gft_rpca(gauss, F).frames, A, F) / mean_theta(gauss, A, F)
    ratio_mask = mean_theta(dyn.gft_rpca(mask, F).frames, A, F) / mean_theta(mask, A, F)
    assert ratio_gauss < 0.5
    assert ratio_mask > 0.9


def test_normals_rpca_denoises(anim):
    A, F = anim
    An = noise.animation_noise(A, F, kind="gaussian", level=0.2, rng=2)
    res = dyn.normals_rpca(An, F)
    assert res.frames.shape == A.shape
    assert np.allclose(np.linalg.norm(res.normals, axis=2), 1.0)
    assert mean_theta(res.frames, A, F) < 0.5 * mean_theta(An, A, F)
    again = denoise_animation(An, F, method="normals-rpca")
    np.testing.assert_allclose(again, res.frames)


def test_static_method_runs_frame_by_frame(anim):
    A, F = anim
    An = noise.animation_noise(A[:3], F, kind="gaussian", level=0.2, rng=0)
    out = denoise_animation(An, F, method="laplacian")
    ref = np.stack([denoise(An[t], F, method="laplacian") for t in range(3)])
    np.testing.assert_allclose(out, ref)


def test_memory_is_bounded_for_partitioned_basis():
    """Peak memory is a small multiple of the animation itself (no n x n matrices)."""
    A, F = waving_grid(T=40, n=45, seed=2)  # 2025 vertices: a dense basis alone would be 33 MB
    An = noise.animation_noise(A, F, kind="gaussian", level=0.2, rng=0)
    dyn.gft_rpca(
        An[:2], F, options=dyn.GFTRPCAOptions(submesh_size=300)
    )  # warm up imports / caches
    tracemalloc.start()
    try:
        dyn.gft_rpca(An, F, options=dyn.GFTRPCAOptions(submesh_size=300))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 8 * An.nbytes + 8 * 300**2 * 8


# --------------------------------------------------------------------------- shared data
def test_shared_chicken_beats_per_frame_bnf(shared_data):
    from spectrageo.io import read_animation

    anim = read_animation(shared_data / "animations" / "chickenCrossing.npz")
    A = np.asarray(anim.frames[:24], dtype=np.float64)
    F = anim.faces
    An = noise.animation_noise(A, F, kind="gaussian", level=0.2, rng=0)
    out = dyn.gft_rpca(An, F).frames
    assert mean_theta(out, A, F) < 0.6 * mean_theta(An, A, F)
    sub = slice(0, 24, 4)
    bnf = mean_theta(dyn.denoise_frames(An[sub], F, method="bnf"), A[sub], F)
    assert mean_theta(out[sub], A[sub], F) < bnf


def test_evaluate_harness(shared_data, tmp_path):
    from spectrageo.evaluate import denoise_dynamic as ev

    rows = ev.evaluate(
        shared_data,
        methods=["gft-rpca", "no-such-method"],
        out=tmp_path / "dyn",
        animations=["chickenCrossing"],
        noises=(("gaussian", 0.2),),
        max_frames=8,
        hd_frames=2,
    )
    assert [r["method"] for r in rows] == ["noisy", "gft-rpca", "no-such-method"]
    assert rows[1]["theta_deg"] < rows[0]["theta_deg"]
    assert rows[1]["kg"] < rows[0]["kg"]
    assert rows[2]["note"] == "unavailable" and np.isnan(rows[2]["theta_deg"])
    md = (tmp_path / "dyn.md").read_text()
    assert "| chickenCrossing | 3030 | 8 | gaussian 0.2 | gft-rpca | **" in md
    assert (tmp_path / "dyn.csv").read_text().count("\n") == 4
    assert ev.format_markdown(rows).count("\n") == 4
    with pytest.raises(InvalidInputError, match="unknown animation"):
        ev.evaluate(shared_data, animations=["nope"])
    with pytest.raises(InvalidInputError, match="max_frames"):
        ev.evaluate(shared_data, max_frames=1)
    with pytest.raises(InvalidInputError, match="methods"):
        ev.evaluate(shared_data, methods=[])
    with pytest.raises(InvalidInputError, match="data_dir"):
        ev.evaluate(tmp_path / "missing")


def test_cli_denoise_animation(tmp_path):
    from spectrageo import io
    from spectrageo.cli.main import main

    A, F = waving_grid(T=6)
    An = noise.animation_noise(A, F, kind="gaussian", level=0.2, rng=0)
    src, dst = tmp_path / "in.npz", tmp_path / "out.npz"
    io.write(src, MeshAnimation(An, F))
    assert main(["denoise", str(src), str(dst), "--method", "gft-rpca"]) == 0
    out = io.read(dst)
    assert isinstance(out, MeshAnimation)
    np.testing.assert_array_equal(out.faces, F)
    ref = denoise_animation(io.read(src).frames, F, method="gft-rpca")
    np.testing.assert_allclose(out.frames, ref, atol=1e-6)


# --------------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"energy": 0.0}, "energy"),
        ({"energy": 1.5}, "energy"),
        ({"energy": "x"}, "energy"),
        ({"rank": 0}, "rank"),
        ({"rank": 1.5}, "rank"),
        ({"lam": -1.0}, "lam"),
        ({"basis": "fast"}, "basis"),
        ({"submesh_solver": "svd"}, "submesh_solver"),
        ({"submesh_size": 0}, "submesh_size"),
        ({"block_size": 0}, "block_size"),
        ({"block_size": 2.5}, "block_size"),
        ({"max_iter": 0}, "max_iter"),
        ({"tol": 0.0}, "tol"),
        ({"rng": "seed"}, "rng"),
    ],
)
def test_gft_rpca_validation(kwargs, match):
    A, F = waving_grid(T=3, n=5)
    fields = {f.name for f in dataclasses.fields(dyn.GFTRPCAOptions)}
    rest = {k: v for k, v in kwargs.items() if k not in fields}
    with pytest.raises(InvalidInputError, match=match):
        opts = dyn.GFTRPCAOptions(**{k: v for k, v in kwargs.items() if k in fields})
        dyn.gft_rpca(A, F, options=opts, **rest)


def test_frames_and_faces_validation(monkeypatch):
    A, F = waving_grid(T=3, n=5)
    with pytest.raises(InvalidInputError, match=r"`frames` must have shape \(T, n, 3\)"):
        dyn.gft_rpca(A[0], F)
    with pytest.raises(InvalidInputError, match="`frames` is empty"):
        dyn.gft_rpca(A[:0], F)
    bad = A.copy()
    bad[1, 2, 0] = np.nan
    with pytest.raises(InvalidInputError, match="NaN or inf"):
        dyn.gft_rpca(bad, F)
    with pytest.raises(InvalidInputError, match="numeric array"):
        dyn.gft_rpca([[["a", "b", "c"]]], F)
    with pytest.raises(InvalidInputError, match="`F` is required"):
        dyn.gft_rpca(A)
    with pytest.raises(InvalidInputError, match="`F` must have shape"):
        dyn.gft_rpca(A, F[:, :2])
    monkeypatch.setattr(dyn, "EXACT_LIMIT", 10)
    with pytest.raises(InvalidInputError, match="limited to 10 vertices"):
        dyn.gft_rpca(A, F, options=dyn.GFTRPCAOptions(basis="exact"))


def test_normals_rpca_and_dispatch_validation():
    A, F = waving_grid(T=3, n=5)
    with pytest.raises(InvalidInputError, match="rank"):
        dyn.normals_rpca(A, F, rank=0)
    with pytest.raises(InvalidInputError, match="lam"):
        dyn.normals_rpca(A, F, lam=0.0)
    with pytest.raises(InvalidInputError, match="n_update"):
        dyn.normals_rpca(A, F, n_update=-1)
    with pytest.raises(InvalidInputError, match="unknown option"):
        denoise_animation(A, F, method="gft-rpca", preset="x")
    with pytest.raises(InvalidInputError, match="unknown denoising method"):
        denoise_animation(A, F, method="nope")
    with pytest.raises(InvalidInputError, match="`method` must be a string"):
        denoise_animation(A, F, method=3)
