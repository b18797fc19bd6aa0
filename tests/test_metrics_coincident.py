"""Surface distances on meshes made of coincident copies (instanced scenes, stacked soups)."""

from __future__ import annotations

import numpy as np
import trimesh

from spectrageo.metrics.surface import _distinct_triangles, point_to_surface


def _copies(k: int):
    m = trimesh.creation.icosphere(subdivisions=2)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    n = V.shape[0]
    Vk = np.vstack([V] * k)
    Fk = np.vstack([np.roll(F, i % 3, axis=1) + i * n for i in range(k)])  # corners rotated
    return V, F, Vk, Fk


def test_copies_give_the_distances_of_one_copy():
    V, F, Vk, Fk = _copies(40)
    P = np.random.default_rng(0).normal(size=(500, 3))
    one = point_to_surface(P, V, F)
    many = point_to_surface(P, Vk, Fk)
    np.testing.assert_allclose(many.distances, one.distances, rtol=1e-12, atol=0)  # corner order
    # the closest face is one of the copies of the same triangle
    np.testing.assert_array_equal(np.sort(Fk[many.face_index] % V.shape[0], axis=1),
                                  np.sort(F[one.face_index], axis=1))  # fmt: skip


def test_only_exact_copies_are_merged():
    V, F, Vk, Fk = _copies(3)
    keep = _distinct_triangles(Vk, Fk)
    assert keep is not None and keep.size == F.shape[0]
    Vk = Vk.copy()
    Vk[-1] += 1e-12  # one corner of the last copy moves: its faces stay
    keep = _distinct_triangles(Vk, Fk)
    moved = np.flatnonzero((Fk == Vk.shape[0] - 1).any(axis=1))
    assert keep.size == F.shape[0] + moved.size and set(moved) <= set(keep)
    assert _distinct_triangles(V, F) is None  # nothing to merge: the faces are used as given
