"""Data model validation and behaviour."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import InvalidInputError, Mesh, MeshAnimation, PointCloud, PointCloudSequence
from spectrageo._validation import as_rng, check_positive
from spectrageo.geometry import (
    clean_mesh,
    degenerate_faces,
    merge_duplicate_vertices,
    remove_unreferenced,
)

from conftest import cube


def test_mesh_upcasts_and_does_not_copy_semantics():
    V, F = cube(1)
    m = Mesh(V.astype(np.float32), F.astype(np.int32))
    assert m.vertices.dtype == np.float64 and m.faces.dtype == np.int64
    assert m.n_vertices == 8 and m.n_faces == 12
    lo, hi = m.bbox()
    np.testing.assert_allclose(lo, -1)
    np.testing.assert_allclose(hi, 1)


def test_mesh_attributes_and_with_vertices():
    V, F = cube(1)
    m = Mesh(V, F, vertex_attributes={"q": np.arange(8.0)}, face_attributes={"s": np.ones(12)})
    m2 = m.with_vertices(V * 2)
    assert m2.vertex_attributes["q"][3] == 3 and np.allclose(m2.vertices, 2 * V)


def test_animation_and_sequence():
    V, F = cube(1)
    frames = np.stack([V, V + 1, V + 2])
    a = MeshAnimation(frames, F)
    assert (a.n_frames, a.n_vertices, a.n_faces) == (3, 8, 12)
    assert np.allclose(a.frame(2).vertices, V + 2) and len(list(a)) == 3
    b = MeshAnimation.from_meshes([Mesh(V, F), Mesh(V + 1, F)])
    assert b.n_frames == 2
    s = PointCloudSequence([V, V[:5]])
    assert s.n_points == [8, 5] and not s.is_fixed_size()
    with pytest.raises(InvalidInputError, match="different point counts"):
        s.as_array()
    pc = PointCloud(V, colors=np.zeros((8, 3), np.uint8), attributes={"i": np.arange(8)})
    sub = pc.select(np.arange(8) % 2 == 0)
    assert (
        sub.n_points == 4
        and sub.colors.shape == (4, 3)
        and list(sub.attributes["i"]) == [0, 2, 4, 6]
    )


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda V, F: Mesh(V[:, :2], F), r"`vertices` must have shape \(n, 3\)"),
        (lambda V, F: Mesh(V, F[:, :2]), r"`faces` must have shape \(m, 3\)"),
        (lambda V, F: Mesh(V, F + 100), "out of range"),
        (lambda V, F: Mesh(V, -F - 1), "out of range"),
        (lambda V, F: Mesh(np.zeros((0, 3)), np.zeros((0, 3), int)), "empty"),
        (lambda V, F: Mesh(V, np.zeros((0, 3), int)), "empty"),
        (lambda V, F: Mesh(np.where(V > 0.5, np.inf, V), F), "NaN or inf"),
        (lambda V, F: Mesh(V, F.astype(np.complex128)), "integer"),
        (
            lambda V, F: Mesh(V, F, vertex_normals=np.ones((3, 3))),
            "`vertex_normals` must have shape",
        ),
        (lambda V, F: Mesh(V, F, vertex_colors=np.ones((8, 5))), "`vertex_colors` must have shape"),
        (lambda V, F: Mesh(V, F, face_attributes={"x": np.ones(3)}), "face attribute `x`"),
        (lambda V, F: Mesh("abc", F), "numeric array"),
        (lambda V, F: PointCloud(V, normals=np.full((8, 3), np.nan)), "`normals` contains NaN"),
        (lambda V, F: PointCloud(V, colors=np.ones((7, 3))), "`colors` must have shape"),
        (lambda V, F: MeshAnimation(V, F), r"`frames` must have shape \(T, n, 3\)"),
        (lambda V, F: MeshAnimation(np.zeros((0, 8, 3)), F), "`frames` is empty"),
        (lambda V, F: MeshAnimation(np.stack([V, V * np.nan]), F), "frame 1"),
        (lambda V, F: MeshAnimation.from_meshes([]), "at least one frame"),
        (lambda V, F: MeshAnimation.from_meshes([Mesh(V, F), Mesh(V, F[::-1])]), "does not share"),
        (lambda V, F: PointCloudSequence([]), "at least one frame"),
        (lambda V, F: PointCloudSequence([V, np.ones((3, 2))]), "frame 1"),
        (lambda V, F: PointCloud(V).select(np.ones(3, bool)), "`keep` mask"),
    ],
)
def test_validation(make, match):
    V, F = cube(1)
    with pytest.raises(InvalidInputError, match=match):
        make(V, F)


def test_repairs_documented_policies():
    V, F = cube(1)
    # duplicate vertex 8 == vertex 0, a degenerate face, a duplicate face and an unreferenced vertex 9
    V2 = np.vstack([V, V[0], [5.0, 5, 5]])
    F2 = np.vstack([F, [[8, 1, 2]], [[0, 0, 1]], F[:1][:, ::-1]])
    assert degenerate_faces(V2, F2).sum() == 1
    m, report = clean_mesh(Mesh(V2, F2), merge_vertices=True)
    assert report.merged_vertices == 1 and report.degenerate_faces == 1
    assert report.duplicate_faces == 1 and report.unreferenced_vertices == 1
    assert m.n_vertices == 8 and m.n_faces == 13
    Vm, Fm, imap = merge_duplicate_vertices(V2, F2)
    assert imap[8] == 0 and len(Vm) == 9
    Vr, Fr, kept = remove_unreferenced(V2, F2)
    assert 9 not in kept and len(Vr) == 9
    m0, r0 = clean_mesh(Mesh(V, F))
    assert not r0.changed and m0.n_vertices == 8


def test_small_validators():
    with pytest.raises(InvalidInputError, match="`rng` must be"):
        as_rng("seed")
    assert as_rng(3).integers(1000) == np.random.default_rng(3).integers(1000)
    with pytest.raises(InvalidInputError, match="must be an integer"):
        check_positive(1.5, "k", integer=True)
    with pytest.raises(InvalidInputError, match="must be a number"):
        check_positive(True, "level")
