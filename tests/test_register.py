"""Registration (thesis Section 6.2): narrow phase, broad phase, robustification, CLI."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from spectrageo import InvalidInputError
from spectrageo.geometry import Mesh, PointCloud
from spectrageo.metrics import registration as rm
from spectrageo.register import (
    RegistrationResult,
    broad_phase,
    narrow_phase,
    register,
    robustify,
)
from spectrageo.register._common import apply_transform, make_transform, random_rotation

from conftest import shared_file


def _small_motion(rng, deg, trans):
    w = rng.normal(size=3)
    w *= np.radians(deg) / np.linalg.norm(w)
    from spectrageo.register._common import rotvec_to_matrix

    t = rng.normal(size=3)
    return make_transform(rotvec_to_matrix(w), t * trans / np.linalg.norm(t))


@pytest.fixture(scope="module")
def bunny(shared_data):
    from spectrageo import io

    folder = shared_file(shared_data, "scans", "bunny", "bun000.ply.gz").parent
    return {n: io.read_point_cloud(folder / f"{n}.ply.gz").points for n in ("bun000", "bun045")}


@pytest.fixture(scope="module")
def bunny_gt(shared_data):
    """Ground truth mapping bun045 onto bun000 from bun.conf (P_world = P @ R(q) + t)."""
    from spectrageo.evaluate.register import bunny_scans

    T = {name: Tw for name, _, Tw in bunny_scans(shared_data)}
    return np.linalg.inv(T["bun000"]) @ T["bun045"]


@pytest.fixture(scope="module")
def model(shared_data):
    from spectrageo import io

    return io.read_mesh(shared_file(shared_data, "meshes", "elephant.off"))


# --------------------------------------------------------------------------- narrow phase
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_narrow_phase_recovers_small_rigid_motion(model, seed):
    rng = np.random.default_rng(seed)
    V = model.vertices
    diag = np.linalg.norm(np.ptp(V, axis=0))
    T_true = _small_motion(rng, 12.0, 0.04 * diag)
    target = apply_transform(T_true, V)
    res = narrow_phase(model, target)  # Mesh input: its vertices
    assert isinstance(res, RegistrationResult)
    assert res.transformation.shape == (4, 4) and res.transformation.dtype == np.float64
    assert res.converged and res.n_iter >= 1
    assert rm.rotation_error_deg(res.transformation, T_true) < 0.05
    assert rm.translation_error(res.transformation, T_true) < 1e-3 * diag
    assert res.fitness > 0.99
    assert res.inlier_rmse < 1e-3 * diag


def test_narrow_phase_coarse_iterations_reach_the_full_set_answer(bunny, bunny_gt, monkeypatch):
    """The strided coarse iterations only speed the start up: the pose equals the one found
    with every iteration on the full source (coarse stage disabled) to a small fraction of the
    noise, and the coarse stage really ran (fewer full-size queries)."""
    import spectrageo.register._narrow as nw

    rng = np.random.default_rng(5)
    init = _small_motion(rng, 10.0, 0.004) @ bunny_gt
    sizes = []
    query = nw._query

    def counting(index, P, bound, eps=0.0):
        sizes.append(P.shape[0])
        return query(index, P, bound, eps)

    monkeypatch.setattr(nw, "_query", counting)
    fast = narrow_phase(bunny["bun045"], bunny["bun000"], init)
    n_fast = list(sizes)
    sizes.clear()
    monkeypatch.setattr(nw, "COARSE_MIN", 10**9)
    full = narrow_phase(bunny["bun045"], bunny["bun000"], init)
    assert min(n_fast) < max(n_fast) == max(sizes) and min(sizes) == max(sizes)
    assert fast.converged and full.converged
    assert rm.rotation_error_deg(fast.transformation, full.transformation) < 0.05
    assert rm.translation_error(fast.transformation, full.transformation) < 2e-4
    assert rm.rotation_error_deg(fast.transformation, bunny_gt) < 0.5


def test_target_index_normals_on_demand_equal_the_whole_computation(model):
    """Normals computed lazily for the paired target points, in any order and with repeats,
    are bit for bit those of one computation over the whole target."""
    from spectrageo.register._common import knn_normals
    from spectrageo.register._narrow import TargetIndex

    V = model.vertices
    index = TargetIndex(V)
    full = knn_normals(V, 10, index.tree)[0]
    rng = np.random.default_rng(0)
    for size in (1, 50, 3000, 3000):
        j = rng.integers(0, V.shape[0], size=size)
        np.testing.assert_array_equal(index.normals_at(j), full[j])
    bare = TargetIndex(V, need_normals=False)
    with pytest.raises(RuntimeError, match="without normals"):
        bare.normals_at(np.array([0]))


def test_narrow_phase_point_to_point_and_init(model):
    rng = np.random.default_rng(7)
    V = model.vertices
    diag = np.linalg.norm(np.ptp(V, axis=0))
    T_true = _small_motion(rng, 40.0, 0.2 * diag)
    target = apply_transform(T_true, V)
    # init close to the answer: 3 degrees off
    init = _small_motion(rng, 3.0, 0.01 * diag) @ T_true
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = narrow_phase(V, target, init, method="point_to_point", max_iter=100)
    assert rm.rotation_error_deg(res.transformation, T_true) < 0.5
    assert rm.translation_error(res.transformation, T_true) < 5e-3 * diag


def test_narrow_phase_tukey_rejects_outliers(model):
    """Points of the target far from the source (clutter) do not bias the result."""
    rng = np.random.default_rng(3)
    V = model.vertices
    diag = np.linalg.norm(np.ptp(V, axis=0))
    T_true = _small_motion(rng, 8.0, 0.03 * diag)
    clutter = V.mean(0) + rng.normal(scale=0.5 * diag, size=(V.shape[0] // 5, 3))
    source = np.r_[V, clutter]  # a fifth of the source has no counterpart
    res = narrow_phase(source, apply_transform(T_true, V))
    assert rm.rotation_error_deg(res.transformation, T_true) < 0.2
    assert rm.translation_error(res.transformation, T_true) < 2e-3 * diag


def test_narrow_phase_on_real_scan_pair(bunny, bunny_gt):
    """From 4 degrees off the ground truth, the partial-overlap scans snap back."""
    rng = np.random.default_rng(0)
    init = _small_motion(rng, 4.0, 0.005) @ bunny_gt
    res = narrow_phase(bunny["bun045"], bunny["bun000"], init)
    assert rm.rotation_error_deg(res.transformation, bunny_gt) < 0.5
    assert rm.translation_error(res.transformation, bunny_gt) < 0.002  # bunny diag ~0.2 m
    assert 0.6 < res.fitness < 1.0  # partial overlap


# --------------------------------------------------------------------------- broad + narrow
def test_register_recovers_large_rotation_on_real_scans(bunny, bunny_gt):
    rng = np.random.default_rng(11)
    M = make_transform(random_rotation(rng), rng.normal(size=3) * 0.05)
    source = apply_transform(M, bunny["bun045"])
    T_gt = bunny_gt @ np.linalg.inv(M)
    assert rm.rotation_error_deg(np.eye(4), T_gt) > 30  # the motion is large
    res = register(source, PointCloud(bunny["bun000"]), rng=0)
    assert rm.rotation_error_deg(res.transformation, T_gt) < 1.0
    assert rm.translation_error(res.transformation, T_gt) < 0.002
    assert res.info["n_candidates"] > 0 and res.info["time_s"] > 0
    # the broad phase alone is already within the narrow phase's basin
    T0 = broad_phase(source, bunny["bun000"], rng=0)
    assert rm.rotation_error_deg(T0, T_gt) < 5.0


def test_register_is_deterministic_for_a_seed(bunny):
    rng = np.random.default_rng(5)
    M = make_transform(random_rotation(rng), np.zeros(3))
    S = apply_transform(M, bunny["bun045"])[::3]
    T = bunny["bun000"][::3]
    a = register(S, T, rng=4)
    b = register(S, T, rng=np.random.default_rng(4))
    np.testing.assert_array_equal(a.transformation, b.transformation)
    assert a.fitness == b.fitness
    assert np.array_equal(broad_phase(S, T, rng=9), broad_phase(S, T, rng=9))


def test_register_with_init_skips_broad_phase(bunny, bunny_gt):
    res = register(bunny["bun045"], bunny["bun000"], init=bunny_gt)
    assert res.info["broad_time_s"] == 0.0
    assert rm.rotation_error_deg(res.transformation, bunny_gt) < 0.5


# --------------------------------------------------------------------------- robustify
def test_robustify_removes_outliers_and_sparse_fringe():
    rng = np.random.default_rng(0)
    g = np.linspace(0, 1, 60)
    x, y = np.meshgrid(g, g)
    plane = np.c_[x.ravel(), y.ravel(), 0.002 * rng.normal(size=x.size)]
    spikes = np.c_[rng.random((30, 2)), rng.choice([-1, 1], 30) * rng.uniform(0.05, 0.1, 30)]
    far = np.array([[3.0, 3.0, 3.0], [3.2, 3.0, 3.0]])  # isolated pair: the boundary criterion
    P = np.r_[plane, spikes, far]
    kept, keep = robustify(P)
    assert keep.shape == (P.shape[0],) and keep.dtype == bool
    np.testing.assert_array_equal(kept, P[keep])
    assert keep[: plane.shape[0]].mean() > 0.95  # the surface stays
    assert not keep[-2:].any()  # Eq. 6.43: mean kNN distance >= 2 d_bar
    assert keep[plane.shape[0] : -2].mean() < 0.5  # most spikes removed (Eq. 6.42)
    only_b = robustify(P, remove_outliers=False)[1]
    assert not only_b[-2:].any() and only_b[: plane.shape[0]].all()


# --------------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda P: narrow_phase(P[:, :2], P), r"`source` must have shape \(n, 3\)"),
        (lambda P: narrow_phase(P, np.zeros((0, 3))), r"`target` is empty"),
        (lambda P: narrow_phase(np.r_[P, [[np.nan, 0, 0]]], P), r"`source` contains NaN"),
        (lambda P: narrow_phase(P[:2], P), r"`source` must have at least 3 points"),
        (lambda P: narrow_phase(P, None), r"`target` must be an \(n, 3\) array"),
        (lambda P: narrow_phase(P, P, np.eye(3)), r"`init` must have shape \(4, 4\)"),
        (lambda P: narrow_phase(P, P, 2 * np.eye(4)), r"`init` must have last row"),
        (lambda P: narrow_phase(P, P, np.diag([1.0, 1, -1, 1])), r"`init` must be a rigid"),
        (lambda P: narrow_phase(P, P, np.full((4, 4), np.nan)), r"`init` contains NaN"),
        (lambda P: narrow_phase(P, P, max_iter=0), r"`max_iter` must be > 0"),
        (lambda P: narrow_phase(P, P, tol=-1.0), r"`tol` must be > 0"),
        (lambda P: narrow_phase(P, P, method="nope"), r"`method` must be one of"),
        (lambda P: narrow_phase(P, P, gamma=0.0), r"`gamma` must be > 0"),
        (lambda P: narrow_phase(P, P, inlier_distance=-1.0), r"`inlier_distance` must be > 0"),
        (lambda P: register(P, P, rng="x"), r"`rng` must be an int seed"),
        (lambda P: register(P, P, broad_options=3), r"`broad_options` must be a dict"),
        (lambda P: register(P[:, :2], P), r"`source` must have shape"),
        (lambda P: broad_phase(P, P, voxel_size=-1.0), r"`voxel_size` must be > 0"),
        (lambda P: broad_phase(P, P, voxel_size=100.0), r"`voxel_size` .* leaves fewer than 6"),
        (lambda P: broad_phase(P, P, n_samples=0), r"`n_samples` must be > 0"),
        (lambda P: broad_phase(P, np.zeros((5, 3))), r"fewer than 6 points|single points"),
        (lambda P: robustify(P, k_boundary=0), r"`k_boundary` must be > 0"),
        (lambda P: robustify(P, outlier_threshold=0), r"`outlier_threshold` must be > 0"),
        (lambda P: robustify(np.ones((4, 4))), r"`points` must have shape"),
    ],
)
def test_validation_errors(call, match):
    rng = np.random.default_rng(0)
    P = rng.random((200, 3))
    with pytest.raises(InvalidInputError, match=match):
        call(P)


def test_accepts_mesh_and_point_cloud_objects():
    rng = np.random.default_rng(1)
    P = rng.random((300, 3)) * [1.0, 0.6, 0.3]
    T_true = _small_motion(rng, 5.0, 0.02)
    m = Mesh(P, np.array([[0, 1, 2]]))
    res = narrow_phase(m, PointCloud(apply_transform(T_true, P)), max_points=1000)
    assert rm.rotation_error_deg(res.transformation, T_true) < 0.5


# --------------------------------------------------------------------------- CLI
def test_cli_register_writes_json_and_moved_source(tmp_path, bunny, bunny_gt):
    from spectrageo import io
    from spectrageo.cli.main import main

    src, tgt = tmp_path / "src.ply", tmp_path / "tgt.ply"
    io.write(src, PointCloud(bunny["bun045"][::4]))
    io.write(tgt, PointCloud(bunny["bun000"][::4]))
    init = tmp_path / "T0.json"
    init.write_text(json.dumps({"transformation": bunny_gt.tolist()}))
    out, moved = tmp_path / "T.json", tmp_path / "moved.ply"
    rc = main(["register", str(src), str(tgt), "--out", str(out), "--init", str(init),
               "--apply", str(moved), "--seed", "3"])  # fmt: skip
    assert rc == 0
    d = json.loads(out.read_text())
    assert {"transformation", "fitness", "inlier_rmse", "converged", "time_s"} <= set(d)
    T = np.asarray(d["transformation"])
    assert T.shape == (4, 4)
    assert rm.rotation_error_deg(T, bunny_gt) < 0.5
    assert 0 < d["fitness"] <= 1 and d["time_s"] > 0
    mv = io.read(moved)
    assert isinstance(mv, PointCloud)
    np.testing.assert_allclose(mv.points, apply_transform(T, bunny["bun045"][::4]), atol=1e-5)


def test_cli_register_errors_are_one_line(tmp_path, capsys):
    from spectrageo.cli.main import main

    p = tmp_path / "a.xyz"
    np.savetxt(p, np.random.default_rng(0).random((50, 3)))
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"transformation": [[1, 0], [0, 1]]}))
    rc = main(["register", str(p), str(p), "--out", str(tmp_path / "T.json"), "--init", str(bad)])
    err = capsys.readouterr().err.strip()
    assert rc != 0 and "4x4" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "T.json").exists()
    rc = main(["register", str(tmp_path / "none.ply"), str(p), "--out", str(tmp_path / "T.json")])
    err = capsys.readouterr().err.strip()
    assert rc != 0 and "file not found" in err and len(err.splitlines()) == 1
