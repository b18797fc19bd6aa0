"""Shared fixtures and helpers: small analytic meshes, the shared data folder, peers.

Missing prerequisites -- the shared data folder, a file in it, a peer library (Open3D, PyMeshLab,
DracoPy), Chromium for the viewer's browser tests -- skip a test on a user's machine with a message
and fail it under ``CI=true``, where ``.ci/run`` installs them all (:func:`skip_or_fail`).
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import NoReturn

import numpy as np
import pytest

from spectrageo.datasets import data_dir

# the peers the differential tests and the benchmarks compare against; .ci/run installs them
PEERS = ("open3d", "pymeshlab", "DracoPy")
_NO_DATA = "shared data not found (set SPECTRAGEO_DATA to the folder ../shared/data)"


def in_ci() -> bool:
    """True under ``CI=true`` (``.ci/run`` exports it; so do GitHub Actions and most CI systems)."""
    return os.environ.get("CI", "").strip().lower() in {"1", "true", "yes"}


def skip_or_fail(reason: str) -> NoReturn:
    """Skip with ``reason`` on a user's machine; fail under ``CI=true``, where nothing may skip
    for a missing prerequisite (the data, the peers and Chromium are always there)."""
    __tracebackhide__ = True  # reports name the calling test's line
    if in_ci():
        pytest.fail(f"{reason} [CI=true: fails instead of skipping]", pytrace=False)
    pytest.skip(reason, allow_module_level=True)


def find_shared_data() -> Path | None:
    """The shared data folder, or None when it is absent: a folder without the data's README
    (an empty or wrong ``SPECTRAGEO_DATA``) counts as absent."""
    d = data_dir()
    if d is None or not (d / "README.md").is_file():
        return None
    return d


def optional_shared_data() -> Path | None:
    """For tests that use real files when present and synthetic ones otherwise: the folder, or
    None on a user's machine without it; fails under ``CI=true`` when it is absent."""
    __tracebackhide__ = True  # reports name the calling test's line
    d = find_shared_data()
    if d is None and in_ci():
        pytest.fail(_NO_DATA + " [CI=true: the real files must be used]", pytrace=False)
    return d


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of the shared data folder (:func:`skip_or_fail` when it is absent)."""
    d = find_shared_data()
    if d is None:
        skip_or_fail(_NO_DATA)
    return d


def shared_file(root: Path, *parts: str) -> Path:
    """``root / parts`` (a file or folder of the shared data); :func:`skip_or_fail` when absent."""
    __tracebackhide__ = True  # reports name the calling test's line
    p = Path(root).joinpath(*parts)
    if not p.exists():
        skip_or_fail(f"{'/'.join(parts)} not found in the shared data folder {root}")
    return p


def require_module(name: str):
    """Import ``name`` (a peer or an optional extra) or :func:`skip_or_fail`. Any exception counts
    as missing: Open3D's wheel raises OSError when libusb-1.0 is not installed."""
    __tracebackhide__ = True  # reports name the calling test's line
    try:
        return importlib.import_module(name)
    except Exception as exc:  # noqa: BLE001 - ImportError, OSError (missing shared library), ...
        skip_or_fail(f"{name} is not usable: {type(exc).__name__}: {exc}")


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


def outlier_recall_precision(
    keep: np.ndarray, injected: np.ndarray, detectable: np.ndarray | None = None
) -> tuple[float, float]:
    """``(recall, precision)`` of the points a filter removed (``~keep``) against the injected
    outliers: recall over ``detectable`` (default: all injected; pass the injected outliers that
    lie far enough from the surface to be told apart from it), precision over all removed points
    (a removed injected outlier, detectable or not, is a true positive). A filter that keeps every
    outlier has recall 0; one that removes nothing has precision 0."""
    removed = ~np.asarray(keep, dtype=bool)
    injected = np.asarray(injected, dtype=bool)
    target = injected if detectable is None else np.asarray(detectable, dtype=bool)
    recall = np.count_nonzero(removed & target) / max(np.count_nonzero(target), 1)
    precision = np.count_nonzero(removed & injected) / max(np.count_nonzero(removed), 1)
    return float(recall), float(precision)
