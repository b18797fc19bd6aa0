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
