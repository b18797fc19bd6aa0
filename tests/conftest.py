"""Shared fixtures: small analytic meshes and access to the shared data folder."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo.datasets import data_dir


@pytest.fixture(scope="session")
def shared_data():
    """Path of the shared data folder; tests needing it skip with a message when it is absent."""
    d = data_dir()
    if d is None:
        pytest.skip("shared data not found (set SPECTRAGEO_DATA to the folder ../shared/data)")
    return d


def icosphere(subdivisions: int = 2):
    """Unit icosphere (V, F) with outward-oriented faces."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def cube(subdiv: int = 4):
    """Closed unit cube [-1, 1]^3 triangulated with ``subdiv`` x ``subdiv`` quads per side, outward."""
    import trimesh

    m = trimesh.creation.box(extents=(2, 2, 2))
    for _ in range(max(0, subdiv - 1)):
        m = m.subdivide()
    m.merge_vertices()
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def irregular_cube(n_edge: int = 5, n_inner: int = 40, seed: int = 0):
    """Closed unit cube [0, 1]^3 whose faces are Delaunay triangulations of ``n_edge + 1`` evenly
    spaced points per cube edge (shared by both faces) and ``n_inner`` random interior points:
    creases with irregular vertex rings, as CAD meshers make them. Outward faces."""
    from scipy.spatial import Delaunay

    g = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n_edge + 1)
    ids: dict = {}
    V: list = []
    F: list = []
    for axis in range(3):
        u_ax, v_ax = [a for a in range(3) if a != axis]
        for side in (0.0, 1.0):
            uv = [(a, b) for a in t for b in t if a in (0.0, 1.0) or b in (0.0, 1.0)]
            uv = np.array(uv + [tuple(x) for x in g.uniform(0.03, 0.97, (n_inner, 2))])
            face_ids = []
            for a, b in uv:
                p = np.zeros(3)
                p[axis], p[u_ax], p[v_ax] = side, a, b
                key = tuple(np.round(p, 9))
                if key not in ids:
                    ids[key] = len(V)
                    V.append(p)
                face_ids.append(ids[key])
            face_ids = np.array(face_ids)
            out = np.zeros(3)
            out[axis] = 1.0 if side == 1.0 else -1.0
            for tri in Delaunay(uv).simplices:
                f = face_ids[tri]
                P = np.array([V[i] for i in f])
                if np.cross(P[1] - P[0], P[2] - P[0]) @ out < 0:
                    f = f[[0, 2, 1]]
                F.append(f)
    return np.array(V), np.array(F, dtype=np.int64)


def grid(nx: int = 10, ny: int = 10):
    """Flat triangulated grid in the z = 0 plane, (V, F)."""
    x, y = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny), indexing="ij")
    V = np.c_[x.ravel(), y.ravel(), np.zeros(nx * ny)]
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = (
        idx[:-1, :-1].ravel(),
        idx[1:, :-1].ravel(),
        idx[1:, 1:].ravel(),
        idx[:-1, 1:].ravel(),
    )
    F = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    return V, F


@pytest.fixture
def sphere_mesh():
    return icosphere(3)


@pytest.fixture
def cube_mesh():
    return cube(4)


@pytest.fixture
def grid_mesh():
    return grid()
