"""Topology report (geometry.topology.mesh_topology): analytic cases, invariances, differential
checks against trimesh and the repair helpers, and the shared meshes."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import InvalidInputError
from spectrageo.geometry import boundary_loops, duplicate_faces, mesh_topology

from conftest import cube, grid, icosphere, shared_file

TET_V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
TET_F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])


def torus(nu: int = 12, nv: int = 8, R: float = 2.0, r: float = 0.5):
    """Periodic nu x nv grid on a torus: V = nu nv, E = 3 nu nv, F = 2 nu nv, chi = 0."""
    u, v = np.meshgrid(
        2 * np.pi * np.arange(nu) / nu, 2 * np.pi * np.arange(nv) / nv, indexing="ij"
    )
    V = np.c_[
        ((R + r * np.cos(v)) * np.cos(u)).ravel(),
        ((R + r * np.cos(v)) * np.sin(u)).ravel(),
        (r * np.sin(v)).ravel(),
    ]
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, ((i + 1) % nu) * nv + j
    c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    F = np.r_[np.c_[a.ravel(), b.ravel(), c.ravel()], np.c_[a.ravel(), c.ravel(), d.ravel()]]
    return V, F


def annulus(nt: int = 16, nr: int = 4):
    """Flat ring, periodic in the angle and open in the radius: two boundary loops, chi = 0."""
    t, rad = np.meshgrid(2 * np.pi * np.arange(nt) / nt, np.linspace(1, 2, nr), indexing="ij")
    V = np.c_[(rad * np.cos(t)).ravel(), (rad * np.sin(t)).ravel(), np.zeros(nt * nr)]
    i, j = np.meshgrid(np.arange(nt), np.arange(nr - 1), indexing="ij")
    a, b = i * nr + j, ((i + 1) % nt) * nr + j
    c, d = ((i + 1) % nt) * nr + j + 1, i * nr + j + 1
    F = np.r_[np.c_[a.ravel(), b.ravel(), c.ravel()], np.c_[a.ravel(), c.ravel(), d.ravel()]]
    return V, F


def bowtie():
    """Two triangles sharing vertex 0 only."""
    V = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [-1, 0, 0], [-1, -1, 0]])
    return V, np.array([[0, 1, 2], [0, 3, 4]])


def test_tetrahedron_is_a_closed_genus_0_manifold():
    t = mesh_topology(TET_V, TET_F.astype(np.int32))
    assert t == {
        "n_vertices": 4,
        "n_faces": 4,
        "n_edges": 6,
        "n_components": 1,
        "n_boundary_loops": 0,
        "n_boundary_edges": 0,
        "n_nonmanifold_edges": 0,
        "n_nonmanifold_vertices": 0,
        "n_duplicate_vertices": 0,
        "n_unreferenced_vertices": 0,
        "n_degenerate_faces": 0,
        "n_duplicate_faces": 0,
        "euler_characteristic": 2,
        "is_closed": True,
        "is_manifold": True,
        "genus": 0,
    }
    # plain Python values (JSON-ready for ``spectrageo info --json``)
    assert all(type(v) in (int, bool) for v in t.values())


@pytest.mark.parametrize(("nu", "nv"), [(12, 8), (5, 3), (30, 20)])
def test_torus_grid_has_genus_1(nu, nv):
    t = mesh_topology(*torus(nu, nv))
    assert t["n_edges"] == 3 * nu * nv
    assert t["euler_characteristic"] == 0 and t["genus"] == 1
    assert t["is_closed"] and t["is_manifold"] and t["n_components"] == 1


def test_single_triangle_and_annulus_boundary_loops():
    t = mesh_topology(TET_V[:3], [[0, 1, 2]])
    assert (t["n_boundary_loops"], t["n_boundary_edges"], t["euler_characteristic"]) == (1, 3, 1)
    assert not t["is_closed"] and t["is_manifold"] and t["genus"] is None
    V, F = annulus(16, 4)
    t = mesh_topology(V, F)
    assert t["n_boundary_loops"] == 2 and t["n_boundary_edges"] == 32
    assert t["euler_characteristic"] == 0 and t["n_components"] == 1 and t["is_manifold"]
    V, F = grid(6, 5)  # a disk: one loop along the 2 (5 + 4) border edges
    t = mesh_topology(V, F)
    assert (t["n_boundary_loops"], t["n_boundary_edges"], t["euler_characteristic"]) == (1, 18, 1)


def test_two_disjoint_triangles_are_two_components():
    V = np.r_[TET_V[:3], TET_V[:3] + 5]
    t = mesh_topology(V, [[0, 1, 2], [3, 4, 5]])
    assert t["n_components"] == 2 and t["n_boundary_loops"] == 2
    assert t["euler_characteristic"] == 2 and t["genus"] is None


def test_three_triangles_on_one_edge():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]])
    t = mesh_topology(V, [[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    assert t["n_nonmanifold_edges"] == 1 and t["n_nonmanifold_vertices"] == 0
    assert not t["is_manifold"] and t["n_boundary_edges"] == 6
    # the six boundary edges form a theta graph through 0 and 1: one connected boundary component
    assert t["n_boundary_loops"] == 1


def test_two_tetrahedra_sharing_a_vertex():
    V = np.r_[TET_V, TET_V[1:] + [0, 0, -2]]
    V[4:] = -TET_V[1:]  # second tetrahedron mirrored through vertex 0
    F = np.r_[TET_F, np.where(TET_F == 0, 0, TET_F + 3)[:, ::-1]]
    t = mesh_topology(V, F)
    # one component (faces connected through a shared vertex), closed, not manifold at vertex 0
    assert t["n_components"] == 1 and t["n_nonmanifold_vertices"] == 1
    assert t["is_closed"] and not t["is_manifold"] and t["genus"] is None
    assert t["euler_characteristic"] == 7 - 12 + 8
    assert t["n_nonmanifold_edges"] == 0


def test_bowtie_counts_two_loops_through_the_pinch():
    V, F = bowtie()
    t = mesh_topology(V, F)
    assert t["n_nonmanifold_vertices"] == 1 and t["n_nonmanifold_edges"] == 0
    assert t["n_components"] == 1 and t["n_boundary_edges"] == 6
    # the figure-eight boundary is two loops meeting at vertex 0, not one
    assert t["n_boundary_loops"] == 2


def test_strip_pinched_onto_itself_has_one_loop():
    # a strip whose two ends touch at one vertex only: one fan per end at that vertex
    V, F = grid(6, 2)  # vertices i * 2 + j, ends 0-1 and 10-11
    F = np.where(F == 10, 0, F)  # glue the end vertex 10 onto 0
    t = mesh_topology(V, F)
    assert t["n_nonmanifold_vertices"] == 1 and t["n_unreferenced_vertices"] == 1
    # the boundary passes twice through 0 (0-2-4-6-8-0 and 0-11-9-...-1-0), but continuing through
    # the fan a walk arrived by, 0-2-...-8-0-11-9-...-1-0 is one loop: the border of the strip
    assert t["n_boundary_loops"] == 1
    assert t["n_components"] == 1 and t["euler_characteristic"] == 0


def test_pinch_counts_do_not_depend_on_order_unlike_a_greedy_walk():
    rng = np.random.default_rng(2)
    V, F = grid(6, 2)
    cases = ((bowtie(), 2), ((V, np.where(F == 10, 0, F)), 1))
    for (V, F), loops in cases:
        greedy = set()
        for _ in range(50):
            perm = rng.permutation(len(V))
            F2 = np.argsort(perm)[F[rng.permutation(len(F))]]
            F2 = np.roll(F2, rng.integers(3), axis=1)
            assert mesh_topology(V[perm], F2)["n_boundary_loops"] == loops
            greedy.add(len(boundary_loops(F2)))
        assert loops in greedy


def test_loop_count_does_not_depend_on_face_order_or_orientation():
    rng = np.random.default_rng(0)
    for V, F in (bowtie(), annulus(10, 3), grid(6, 2), torus(6, 4)):
        ref = mesh_topology(V, F)
        for _ in range(5):
            F2 = F[rng.permutation(len(F))]
            flip = rng.random(len(F2)) < 0.5
            F2[flip] = F2[flip][:, ::-1]
            F2 = np.roll(F2, rng.integers(3), axis=1)
            perm = rng.permutation(len(V))  # relabel the vertices too
            inv = np.argsort(perm)
            assert mesh_topology(V[perm], inv[F2]) == ref


def test_duplicate_vertices_in_a_two_triangle_soup():
    P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    V = P[[0, 1, 2, 1, 3, 2]]  # the shared edge 1-2 written twice
    t = mesh_topology(V, [[0, 1, 2], [3, 4, 5]])
    assert t["n_duplicate_vertices"] == 2
    assert t["n_components"] == 2 and t["n_boundary_loops"] == 2  # not welded: two triangles
    t = mesh_topology(P, [[0, 1, 2], [1, 3, 2]])  # welded: one square, one loop
    assert t["n_duplicate_vertices"] == 0
    assert t["n_components"] == 1 and t["n_boundary_loops"] == 1


def test_degenerate_duplicate_and_unreferenced_elements():
    t = mesh_topology(TET_V, np.r_[TET_F, [[0, 0, 1]]])
    assert t["n_degenerate_faces"] == 1
    V = np.r_[TET_V, [[0.5, 0, 0]]]  # on the edge 0-1: a zero-area face with distinct indices
    t = mesh_topology(V, np.r_[TET_F, [[0, 1, 4]]])
    assert t["n_degenerate_faces"] == 1 and t["n_unreferenced_vertices"] == 0
    t = mesh_topology(np.r_[TET_V, [[9.0, 9, 9]]], TET_F)
    assert t["n_unreferenced_vertices"] == 1
    # an isolated vertex is neither a component nor part of chi
    assert t["n_components"] == 1 and t["euler_characteristic"] == 2 and t["genus"] == 0
    t = mesh_topology(TET_V, np.r_[TET_F, TET_F[:1, ::-1]])
    assert t["n_duplicate_faces"] == 1 and t["n_nonmanifold_edges"] == 3


def test_duplicate_faces_agree_with_repair_helper():
    rng = np.random.default_rng(1)
    V = rng.normal(size=(8, 3))
    for _ in range(20):
        F = rng.integers(0, 8, size=(30, 3))
        F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
        t = mesh_topology(V, F)
        assert t["n_duplicate_faces"] == int(duplicate_faces(F).sum())


def test_agrees_with_trimesh():
    import trimesh

    for V, F in (icosphere(2), cube(3), grid(7, 4), torus(9, 5), annulus(12, 3)):
        t = mesh_topology(V, F)
        tm = trimesh.Trimesh(V, F, process=False)
        assert t["euler_characteristic"] == tm.euler_number
        assert t["is_closed"] == tm.is_watertight
        assert t["n_boundary_loops"] == len(boundary_loops(F))  # manifold: the walks agree


def test_empty_faces():
    t = mesh_topology(TET_V, np.zeros((0, 3), dtype=np.int64))
    assert t["n_components"] == 0 and t["n_unreferenced_vertices"] == 4
    assert not t["is_closed"] and t["genus"] is None and t["euler_characteristic"] == 0


@pytest.mark.parametrize(
    ("V", "F", "match"),
    [
        (TET_V, TET_F[:, :2], r"`F` must have shape \(m, 3\)"),
        (TET_V, TET_F + 1, "out of range"),
        (TET_V[:, :2], TET_F, r"`V` must have shape \(n, 3\)"),
        (TET_V * np.nan, TET_F, "NaN or inf"),
    ],
)
def test_validation(V, F, match):
    with pytest.raises(InvalidInputError, match=match):
        mesh_topology(V, F)


def test_shared_meshes(shared_data):
    from spectrageo import io

    m = io.read(shared_data / "meshes" / "fandisk.off")
    t = mesh_topology(m.vertices, m.faces)
    assert t["is_closed"] and t["is_manifold"] and t["genus"] == 0
    expected = {  # boundary loops, chi (chi checked against trimesh's euler_number)
        "holes.off": (7, -5),
        "mech-holes-shark.off": (4, -2),
        "elephant-with-holes.off": (106, -110),
    }
    for name, (loops, chi) in expected.items():
        path = shared_file(shared_data, "holes", name)
        m = io.read(path)
        t = mesh_topology(m.vertices, m.faces)
        assert (t["n_boundary_loops"], t["euler_characteristic"]) == (loops, chi), name
        assert t["n_boundary_loops"] == len(boundary_loops(m.faces)), name
        assert not t["is_closed"] and t["is_manifold"] and t["n_components"] == 1, name
