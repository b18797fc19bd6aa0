"""Metrics of Section 4.9: analytic cases, independent recomputation, shared pairs, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spectrageo import io, metrics
from spectrageo._errors import InvalidInputError
from spectrageo.cli.main import main as cli

from conftest import cube, icosphere


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
    d = metrics.point_to_surface(sphere_pts, V, F, return_closest=True)
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
        pytest.skip("no denoising pairs in the shared data")
    return pairs


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
        # Hausdorff: brute force on a vertex sample; the sample max bounds hd_max from below and
        # every sampled distance is reproduced by the per-vertex values.
        idx = rng.choice(len(V), size=min(60, len(V)), replace=False)
        brute = _point_triangle_brute(V[idx], Vr[F[:, 0]], Vr[F[:, 1]], Vr[F[:, 2]], chunk=8)
        per_vertex = metrics.surface_distance_per_vertex(V, Vr, F)
        np.testing.assert_allclose(per_vertex[idx], brute, rtol=1e-7, atol=1e-12)
        assert got["hd_max"] == pytest.approx(per_vertex.max(), rel=1e-9)
        assert got["hd_mean"] == pytest.approx(per_vertex.mean(), rel=1e-9)
        assert got["hd_mean"] <= got["dmean"] + 1e-12  # surface is closer than the vertex


def test_cli_metrics_mismatched_pair_is_one_line_error(shared_data, capsys):
    pairs = _pairs(shared_data)
    (_, a, _), (_, b, _) = pairs[0], pairs[-1]
    assert cli(["metrics", str(a), str(b)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "same number of vertices" in err[0]
