"""Metrics of Section 4.9: analytic cases, independent recomputation, shared pairs, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spectrageo import io, metrics
from spectrageo._errors import InvalidInputError
from spectrageo.cli.main import main as cli

from conftest import cube, icosphere, skip_or_fail


# ------------------------------------------------------------------ independent references
def _normals_ref(V, F):
    """Unit face normals by plain numpy (independent of spectrageo.geometry)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _theta_ref(V, V_ref, F):
    d = np.clip(np.sum(_normals_ref(V, F) * _normals_ref(V_ref, F), axis=1), -1.0, 1.0)
    return float(np.degrees(np.arccos(d)).mean())


def _point_triangle_brute(P, A, B, C, chunk=64):
    """Distance from each point to the nearest of the triangles (A, B, C), brute force.

    Independent reference: the minimum of (a) the distance to the plane when the projection falls
    inside the triangle (barycentric test) and (b) the distances to the three edge segments.
    """
    out = np.empty(len(P))
    ab, ac = B - A, C - A
    nrm = np.cross(ab, ac)
    nn = np.einsum("ij,ij->i", nrm, nrm)
    ok = nn > 0

    def seg(p, s0, s1):
        d = s1 - s0
        dd = np.einsum("ij,ij->i", d, d)
        t = np.where(dd > 0, np.einsum("kij,ij->ki", p - s0, d) / np.where(dd > 0, dd, 1), 0)
        t = np.clip(t, 0, 1)
        return np.linalg.norm(p - (s0 + t[..., None] * d), axis=-1)

    for s in range(0, len(P), chunk):
        p = P[s : s + chunk, None, :]  # (c, 1, 3)
        best = np.minimum(np.minimum(seg(p, A, B), seg(p, B, C)), seg(p, C, A))
        w = p - A
        # barycentric coordinates of the projection
        d00 = np.einsum("ij,ij->i", ab, ab)
        d01 = np.einsum("ij,ij->i", ab, ac)
        d11 = np.einsum("ij,ij->i", ac, ac)
        d20 = np.einsum("kij,ij->ki", w, ab)
        d21 = np.einsum("kij,ij->ki", w, ac)
        den = np.where(ok, d00 * d11 - d01 * d01, 1.0)
        v = (d11 * d20 - d01 * d21) / den
        u = (d00 * d21 - d01 * d20) / den
        inside = ok & (v >= 0) & (u >= 0) & (u + v <= 1)
        plane = np.abs(np.einsum("kij,ij->ki", w, nrm)) / np.sqrt(np.where(ok, nn, 1))
        best = np.where(inside, np.minimum(best, plane), best)
        out[s : s + chunk] = best.min(axis=1)
    return out


def _face_samples_ref(V, F):
    """Corners, edge midpoints and centroids of the faces, each once, with their area weights
    (7-point rule: 3/60 per corner, 8/60 per edge midpoint, 27/60 for the centroid, summed over the
    faces sharing a point)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    corners, inv_c = np.unique(F.ravel(), return_inverse=True)
    w_c = np.bincount(inv_c.ravel(), weights=np.repeat(area, 3) * 3 / 60)
    pairs = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    E, inv_e = np.unique(pairs, axis=0, return_inverse=True)
    w_e = np.bincount(inv_e.ravel(), weights=np.tile(area, 3) * 8 / 60)
    P = np.concatenate([V[corners], (V[E[:, 0]] + V[E[:, 1]]) / 2, (a + b + c) / 3])
    return P, np.concatenate([w_c, w_e, area * 27 / 60])


def _symmetric_brute(P_res, w_res, tri_res, P_ref, w_ref, tri_ref):
    """hd_max, hd_mean (mean of the weighted one-sided means), both directions by brute force.

    ``tri_*`` is None for a point cloud (point-to-point distances), else the (A, B, C) corners.
    """

    def one(P, tgt_pts, tri):
        if tri is None:
            return np.linalg.norm(P[:, None, :] - tgt_pts[None, :, :], axis=2).min(axis=1)
        return _point_triangle_brute(P, *tri, chunk=16)

    d1 = one(P_res, P_ref, tri_ref)
    d2 = one(P_ref, P_res, tri_res)
    return max(d1.max(), d2.max()), 0.5 * (d1 @ w_res / w_res.sum() + d2 @ w_ref / w_ref.sum())


# ------------------------------------------------------------------ analytic
def test_identical_meshes_give_zero_everywhere():
    V, F = icosphere(2)
    d = metrics.compare(V, V, F)
    assert set(d) == set(metrics.METRIC_KEYS)
    for k, v in d.items():
        assert v == pytest.approx(0.0, abs=1e-12), k


def test_translation_moves_positions_not_normals():
    V, F = icosphere(2)
    t = np.array([0.3, -0.4, 0.0])  # |t| = 0.5
    d = metrics.compare(V + t, V, F)
    assert d["theta_deg"] == pytest.approx(0.0, abs=1e-9)
    assert d["dist_n"] == pytest.approx(0.0, abs=1e-12)
    assert d["dmean"] == pytest.approx(0.5) and d["dmax"] == pytest.approx(0.5)
    # GL is translation invariant: NMSVE = (n*0.25)/(2n) / diag^2
    diag2 = np.sum((V.max(0) - V.min(0)) ** 2)
    assert d["nmsve"] == pytest.approx(0.125 / diag2)


def test_rotated_face_gives_exact_angle():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])
    F = np.array([[0, 1, 2], [1, 3, 2]])
    W = V.copy()
    W[3, 2] = 1.0  # tilt the second face
    n2 = _normals_ref(W, F)[1]
    expected = np.degrees(np.arccos(n2 @ np.array([0, 0, 1.0])))
    assert metrics.face_angle_errors(W, V, F) == pytest.approx([0.0, expected])
    assert metrics.theta_deg(W, V, F) == pytest.approx(expected / 2)


def test_flipped_normal_is_180_degrees():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    W = V * np.array([1, 1, -1.0])
    W[:, 0] *= -1  # mirror: orientation flips
    assert metrics.theta_deg(W, V, [[0, 1, 2]]) == pytest.approx(180.0)


def test_hausdorff_to_plane_is_height():
    V, F = cube(3)
    V = V - 0.5
    sphere_pts = np.array([[0.0, 0.0, 1.5], [0.0, 0.0, 0.25], [2.0, 2.0, 2.0]])
    d = metrics.point_to_surface_closest(sphere_pts, V, F)
    assert d.distances[0] == pytest.approx(1.0)
    assert d.distances[1] == pytest.approx(0.25)
    assert d.distances[2] == pytest.approx(np.sqrt(3 * 1.5**2))
    assert np.allclose(d.closest_points[2], [0.5, 0.5, 0.5])


def test_point_to_surface_matches_brute_force():
    rng = np.random.default_rng(1)
    V, F = icosphere(2)
    V = V * rng.uniform(0.7, 1.3, size=(len(V), 1))  # bumpy, non-convex
    P = rng.normal(size=(300, 3)) * 1.2
    got = metrics.point_to_surface(P, V, F).distances
    ref = _point_triangle_brute(P, V[F[:, 0]], V[F[:, 1]], V[F[:, 2]])
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)


def test_compare_hd_is_symmetric_and_matches_brute_force():
    rng = np.random.default_rng(3)
    V, F = icosphere(1)
    W = V * rng.uniform(0.8, 1.2, size=(len(V), 1))
    d = metrics.compare(W, V, F)
    tri = lambda X: (X[F[:, 0]], X[F[:, 1]], X[F[:, 2]])  # noqa: E731
    Pw, ww = _face_samples_ref(W, F)
    Pv, wv = _face_samples_ref(V, F)
    hd_max, hd_mean = _symmetric_brute(Pw, ww, tri(W), Pv, wv, tri(V))
    assert d["hd_max"] == pytest.approx(hd_max, rel=1e-9)
    assert d["hd_mean"] == pytest.approx(hd_mean, rel=1e-9)
    swapped = metrics.compare(V, W, F)
    assert swapped["hd_max"] == d["hd_max"] and swapped["hd_mean"] == d["hd_mean"]
    assert d["hd_max"] <= d["dmax"] + 1e-12


def test_centroid_collapse_is_not_scored_zero():
    """Every face shrunk to (almost) its centroid, as a triangle soup: the result lies on the
    reference surface (one-sided distance ~0), the symmetric distance is of the order of the faces'
    size (a reference vertex is ~0.58 edge lengths from the nearest centroid)."""
    V, F = icosphere(2)
    Vs, Fs = V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3)
    C = np.repeat(V[F].mean(axis=1), 3, axis=0)
    Vc = C + 1e-3 * (Vs - C)
    edge = np.linalg.norm(V[F[:, 1]] - V[F[:, 0]], axis=1)
    assert metrics.hausdorff(Vc, None, Vs, Fs, symmetric=False).hd_max < 1e-12  # the old score
    d = metrics.compare(Vc, Vs, Fs)
    assert 0.5 * edge.min() < d["hd_max"] <= edge.max()
    assert d["theta_deg"] < 1e-6  # the normals alone do not see it
    # the centroids as a point cloud against the mesh
    s = metrics.compare_surfaces(V[F].mean(axis=1), (V, F))
    assert s["hd_max_to_reference"] < 1e-12
    assert 0.5 * edge.min() < s["hd_max"] == s["hd_max_to_result"] <= edge.max()
    assert s["precision"] == 1.0 and s["recall"] < 1.0


def test_unreferenced_vertex_is_not_part_of_the_surface():
    V, F = icosphere(2)
    V2 = np.vstack([V, [[10.0, 0.0, 0.0]]])  # used by no face
    d = metrics.compare(V2, V2, F)
    assert d["hd_max"] < 1e-12 and d["hd_mean"] < 1e-12
    W2 = V2.copy()
    W2[-1] = [-50.0, 3.0, 1.0]  # moving it changes the per-vertex metrics, not the surface ones
    d = metrics.compare(W2, V2, F)
    assert d["hd_max"] < 1e-12 and d["dmax"] > 50
    s = metrics.compare_surfaces((V2, F), (V, F))
    assert s["hd_max"] < 1e-12 and s["n_points_result"] == s["n_points_reference"]
    h = metrics.hausdorff(V2, F, V2, F)
    assert h.hd_symmetric < 1e-12


def test_compare_surfaces_symmetric_on_swap():
    rng = np.random.default_rng(5)
    V, F = icosphere(2)
    W, G = icosphere(3)
    W = W * rng.uniform(0.95, 1.05, size=(len(W), 1))
    cloud = rng.normal(size=(200, 3))
    cloud /= np.linalg.norm(cloud, axis=1, keepdims=True)
    for a, b in (((V, F), (W, G)), ((V, F), cloud), (cloud, cloud[:50] * 1.1)):
        ab = metrics.compare_surfaces(a, b, radius=0.05)
        ba = metrics.compare_surfaces(b, a, radius=0.05)
        for k in ("hd_max", "hd_mean", "chamfer", "fscore"):
            assert ab[k] == pytest.approx(ba[k], rel=1e-12, abs=1e-15), k
        assert ab["precision"] == ba["recall"] and ab["recall"] == ba["precision"]
        assert ab["hd_max_to_reference"] == ba["hd_max_to_result"]
        assert ab["n_points_result"] == ba["n_points_reference"]


def test_compare_surfaces_matches_brute_force_for_every_combination():
    rng = np.random.default_rng(7)
    V, F = icosphere(1)
    W, G = icosphere(2)
    W = W * rng.uniform(0.9, 1.1, size=(len(W), 1)) + 0.05
    P = rng.normal(size=(80, 3)) * 0.7
    Q = rng.normal(size=(60, 3))
    tri = lambda X, T: (X[T[:, 0]], X[T[:, 1]], X[T[:, 2]])  # noqa: E731
    mesh_a = (*_face_samples_ref(V, F), tri(V, F))
    mesh_b = (*_face_samples_ref(W, G), tri(W, G))
    cloud_p = (P, np.ones(len(P)), None)
    cloud_q = (Q, np.ones(len(Q)), None)
    cases = [
        ((V, F), (W, G), mesh_a, mesh_b),
        ((V, F), Q, mesh_a, cloud_q),
        (P, (W, G), cloud_p, mesh_b),
        (P, Q, cloud_p, cloud_q),
    ]
    for a, b, ra, rb in cases:
        got = metrics.compare_surfaces(a, b)
        hd_max, hd_mean = _symmetric_brute(*ra, *rb)
        assert got["hd_max"] == pytest.approx(hd_max, rel=1e-9)
        assert got["hd_mean"] == pytest.approx(hd_mean, rel=1e-9)
        assert got["chamfer"] == got["hd_mean"]


def test_sphere_at_two_resolutions():
    V, F = icosphere(2)
    W, G = icosphere(4)
    s = metrics.compare_surfaces((V, F), (W, G), radius=0.1)
    # chords of a unit sphere: the coarse surface lies within the sagitta of the fine one
    edge = np.linalg.norm(V[F[:, 1]] - V[F[:, 0]], axis=1).max()
    assert s["hd_max"] <= edge**2 / 2 and s["chamfer"] < 0.02  # 2% of the radius
    assert s["fscore"] == 1.0 and s["precision"] == 1.0 and s["recall"] == 1.0
    tiny = metrics.compare_surfaces((V, F), (W, G), radius=1e-4)
    assert 0.0 < tiny["fscore"] < 1.0 and tiny["fscore_radius"] == 1e-4
    assert tiny["chamfer"] == s["chamfer"]
    n_ref = len(W) + len(G) * 3 // 2 + len(G)  # closed mesh: vertices + edges + faces
    assert s["n_points_reference"] == n_ref


def test_translated_cloud_chamfer_is_the_translation():
    g = np.arange(6.0)
    P = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    t = np.array([0.06, -0.08, 0.0])  # |t| = 0.1, far below the spacing 1
    s = metrics.compare_surfaces(P + t, P, radius=0.2)
    assert s["chamfer"] == pytest.approx(0.1) and s["hd_max"] == pytest.approx(0.1)
    assert s["fscore"] == 1.0
    assert metrics.compare_surfaces(P + t, P, radius=0.05)["fscore"] == 0.0
    assert s["n_points_result"] == s["n_points_reference"] == len(P)


def test_fscore_default_radius_is_one_percent_of_reference_diagonal():
    V, F = icosphere(2)
    V2 = np.vstack([V * 3.0, [[100.0, 100.0, 100.0]]])  # unreferenced: not in the bounding box
    s = metrics.compare_surfaces((V, F), (V2, F))
    diag = np.linalg.norm(V.max(0) - V.min(0)) * 3.0
    assert s["fscore_radius"] == pytest.approx(0.01 * diag)
    assert s["fscore"] == 0.0  # radius 1 vs radius 3 spheres


def test_surface_samples_are_a_cubic_quadrature():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [5, 5, 5.0]])  # last unreferenced
    F = np.array([[0, 1, 2], [1, 3, 2]])
    P, w = metrics.surface_samples(V, F)
    assert len(P) == 4 + 5 + 2 and w.sum() == pytest.approx(1.0)
    assert not np.any(np.all(P == [5, 5, 5.0], axis=1))
    # mean of x^3 over the unit square is 1/4; of x*y^2 is 1/6
    assert w @ P[:, 0] ** 3 == pytest.approx(0.25)
    assert w @ (P[:, 0] * P[:, 1] ** 2) == pytest.approx(1 / 6)


def test_compare_surfaces_bad_input():
    V, F = icosphere(1)
    with pytest.raises(InvalidInputError, match="radius"):
        metrics.compare_surfaces((V, F), (V, F), radius=0.0)
    with pytest.raises(InvalidInputError, match="radius"):
        metrics.compare_surfaces((V, F), np.zeros((4, 3)))
    with pytest.raises(InvalidInputError, match="no faces"):
        metrics.compare_surfaces((V, np.zeros((0, 3), dtype=int)), (V, F))
    with pytest.raises(InvalidInputError, match="animation"):
        from spectrageo.geometry import MeshAnimation

        metrics.compare_surfaces(MeshAnimation(np.stack([V, V]), F), (V, F))
    with pytest.raises(InvalidInputError, match="NaN"):
        metrics.compare_surfaces(np.full((3, 3), np.nan), (V, F))


def test_hausdorff_symmetric_and_one_sided():
    V, F = icosphere(2)
    W = V * 1.1
    h = metrics.hausdorff(W, F, V, F, symmetric=True)
    # every vertex of the bigger sphere is 0.1 from a vertex; to the surface it is a bit more
    assert 0.1 <= h.hd_max <= 0.1 + 0.05
    assert h.hd_max_reverse is not None and h.hd_symmetric == max(h.hd_max, h.hd_max_reverse)
    assert h.hd_mean <= h.hd_max
    one = metrics.hausdorff(W, None, V, F, symmetric=True)
    assert one.hd_max_reverse is None


def test_nmsve_normalize_none_is_model_units():
    V, F = icosphere(1)
    W = V * 2.0
    d_bbox = metrics.nmsve(W, V, F)
    d_none = metrics.nmsve(W, V, F, normalize="none")
    diag2 = np.sum((V.max(0) - V.min(0)) ** 2)
    assert d_bbox == pytest.approx(d_none / diag2)


def test_kg_and_sted_zero_for_identical_and_positive_otherwise():
    V, F = icosphere(1)
    frames = np.stack([V * (1 + 0.1 * t) for t in range(5)])
    assert metrics.kg_error(frames, frames) == pytest.approx(0.0, abs=1e-12)
    noisy = frames + np.random.default_rng(0).normal(scale=0.01, size=frames.shape)
    assert metrics.kg_error(noisy, frames) > 0
    s0 = metrics.sted(frames, frames, F)
    s1 = metrics.sted(noisy, frames, F)
    assert float(getattr(s0, "sted", s0)) == pytest.approx(0.0, abs=1e-12)
    assert float(getattr(s1, "sted", s1)) > 0


def test_compare_animation_per_frame_means():
    V, F = icosphere(1)
    frames = np.stack([V, V * 1.2, V * 0.9])
    noisy = frames + np.random.default_rng(0).normal(scale=0.02, size=frames.shape)
    d = metrics.compare_animation(noisy, frames, F)
    per = [metrics.theta_deg(noisy[t], frames[t], F) for t in range(3)]
    assert d["theta_deg"] == pytest.approx(np.mean(per))
    assert "kg" in d and "sted" in d


def test_rotation_and_translation_errors():
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    assert metrics.rotation_error_deg(R, np.eye(3)) == pytest.approx(30.0)
    assert metrics.translation_error([1, 2, 3], [1, 2, 0]) == pytest.approx(3.0)


def test_bits_per_vertex():
    assert metrics.bits_per_vertex(8000, 1000) == pytest.approx(8.0)
    assert metrics.bits_per_vertex(n_bytes=1000, n_vertices=100, n_frames=10) == pytest.approx(8.0)
    with pytest.raises(InvalidInputError, match="exactly one"):
        metrics.bits_per_vertex(8000, 1000, n_bytes=10)


# ------------------------------------------------------------------ bad input
def test_mismatched_vertex_counts():
    V, F = icosphere(1)
    with pytest.raises(InvalidInputError, match="same number of vertices"):
        metrics.compare(V[:-1], V, F)


def test_mismatched_faces():
    V, F = icosphere(1)
    with pytest.raises(InvalidInputError, match="share the same faces"):
        metrics.compare(V, V, F, faces_result=F[:, [0, 2, 1]])


def test_nan_rejected():
    V, F = icosphere(1)
    W = V.copy()
    W[3, 1] = np.nan
    with pytest.raises(InvalidInputError, match="finite|NaN"):
        metrics.compare(W, V, F)


def test_all_degenerate_faces_rejected():
    V = np.zeros((3, 3))
    with pytest.raises(InvalidInputError, match="degenerate"):
        metrics.theta_deg(V, V, [[0, 1, 2]])


def test_faces_required_for_arrays():
    V, _ = icosphere(1)
    with pytest.raises(InvalidInputError, match="`F` is required"):
        metrics.compare(V, V)


def test_nmsve_bad_normalize():
    V, F = icosphere(1)
    with pytest.raises(InvalidInputError, match="normalize"):
        metrics.nmsve(V, V, F, normalize="area")


# ------------------------------------------------------------------ shared pairs through the CLI
def _pairs(shared_data):
    from spectrageo.datasets import denoise_pairs

    pairs = denoise_pairs(shared_data)
    if not pairs:
        skip_or_fail(f"no denoising pairs in the shared data folder {shared_data}")
    return pairs


@pytest.mark.slow
def test_cli_metrics_on_every_shared_pair_agrees_with_independent_computation(shared_data, capsys):
    rng = np.random.default_rng(0)
    for name, noisy, orig in _pairs(shared_data):
        assert cli(["metrics", str(noisy), str(orig), "--json"]) == 0
        got = json.loads(capsys.readouterr().out)
        for k in ("theta_deg", "dmean", "dmax", "dist_n", "dmean_n", "nmsve", "hd_mean", "hd_max"):
            assert k in got and np.isfinite(got[k]), (name, k)
        N, O = io.read_mesh(noisy), io.read_mesh(orig)
        V, Vr, F = N.vertices, O.vertices, O.faces
        e = np.linalg.norm(V - Vr, axis=1)
        assert got["dmean"] == pytest.approx(e.mean(), rel=1e-9), name
        assert got["dmax"] == pytest.approx(e.max(), rel=1e-9), name
        assert got["theta_deg"] == pytest.approx(_theta_ref(V, Vr, F), rel=1e-6), name
        fn, fr = _normals_ref(V, F), _normals_ref(Vr, F)
        assert got["dmean_n"] == pytest.approx(np.linalg.norm(fn - fr, axis=1).mean(), rel=1e-6)
        # Hausdorff, symmetric: each surface sampled at its face corners, edge midpoints and
        # centroids (area weights 3/60, 8/60, 27/60), measured against the other in both directions.
        # The
        # exact distances are checked by brute force on a random subset that includes the sample
        # attaining each one-sided maximum.
        hd_max, means = 0.0, []
        for src, tgt in ((V, Vr), (Vr, V)):
            P, w = _face_samples_ref(src, F)
            d = metrics.point_to_surface(P, tgt, F).distances
            idx = np.r_[rng.choice(len(P), size=min(40, len(P)), replace=False), np.argmax(d)]
            brute = _point_triangle_brute(P[idx], tgt[F[:, 0]], tgt[F[:, 1]], tgt[F[:, 2]], chunk=8)
            np.testing.assert_allclose(d[idx], brute, rtol=1e-7, atol=1e-12)
            hd_max = max(hd_max, d.max())
            means.append(d @ w / w.sum())
        assert got["hd_max"] == pytest.approx(hd_max, rel=1e-9), name
        assert got["hd_mean"] == pytest.approx(np.mean(means), rel=1e-9), name
        assert got["chamfer"] == pytest.approx(np.mean(means), rel=1e-9), name
        assert got["correspondence"] is True
        # corresponding vertices: every surface point has a counterpart at most dmax away
        assert got["hd_max"] <= got["dmax"] + 1e-12


def test_cli_metrics_mismatched_pair_reports_surface_metrics_only(shared_data, capsys):
    pairs = _pairs(shared_data)
    (_, a, _), (_, b, _) = pairs[0], pairs[-1]
    assert cli(["metrics", str(a), str(b), "--json"]) == 0
    cap = capsys.readouterr()
    got = json.loads(cap.out)
    assert got["correspondence"] is False and "theta_deg" not in got and "dmean" not in got
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and "no vertex correspondence" in err[0]
    A, B = io.read_mesh(a), io.read_mesh(b)
    ref = metrics.compare_surfaces(A, B)
    for k in metrics.SURFACE_KEYS:
        assert got[k] == pytest.approx(ref[k], rel=1e-12), k
