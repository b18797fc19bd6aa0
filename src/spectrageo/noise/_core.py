"""Result types and shared helpers of the noise package."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_choice
from ..geometry.primitives import edges, vertex_normals

DIRECTIONS = ("normal", "random")


@dataclass(frozen=True, eq=False)
class NoiseResult:
    """Noisy geometry with its ground truth.

    ``vertices`` and ``displacement`` ((n, 3) or (T, n, 3)): the noisy positions and the exact added
    vectors; ``mask``: the vertices selected for noise; ``scale``: the standard deviation (or
    quantisation step) per vertex in model units; ``labels``: the region of every vertex for
    region-varying noise, else None; ``kind``.
    """

    vertices: np.ndarray
    displacement: np.ndarray
    mask: np.ndarray
    scale: np.ndarray
    labels: np.ndarray | None = None
    kind: str = ""


def check_level(level, name: str = "level") -> float:
    if isinstance(level, bool) or not isinstance(level, int | float | np.integer | np.floating):
        raise InvalidInputError(f"`{name}` must be a number; got {level!r}.")
    if not np.isfinite(level) or level < 0:
        raise InvalidInputError(f"`{name}` must be a finite number >= 0; got {level!r}.")
    return float(level)


def check_fraction(fraction, name: str = "fraction") -> float:
    if isinstance(fraction, bool) or not isinstance(
        fraction, int | float | np.integer | np.floating
    ):
        raise InvalidInputError(f"`{name}` must be a number in [0, 1]; got {fraction!r}.")
    if not np.isfinite(fraction) or fraction < 0 or fraction > 1:
        raise InvalidInputError(f"`{name}` must be in [0, 1]; got {fraction!r}.")
    return float(fraction)


def unique_edges(F: np.ndarray, n: int) -> np.ndarray:
    """Unique undirected edges (i < j) of ``F``, shape (e, 2)."""
    return edges(F)


def mean_spacing(V: np.ndarray, F: np.ndarray | None) -> float:
    """The ``l`` of Eq. (4.36): mean edge length, or mean nearest-neighbour distance for a cloud."""
    if F is not None:
        E = unique_edges(F, V.shape[0])
        if E.shape[0] == 0:
            raise InvalidInputError(
                "the mesh has no edge of non-zero index span; cannot scale noise."
            )
        return float(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).mean())
    if V.shape[0] < 2:
        raise InvalidInputError("a point cloud needs at least 2 points to define the noise scale.")
    from ..graph.adjacency import knn

    _, dist = knn(V, 1)
    return float(dist[:, 0].mean())


def prepare(
    V, F, normals, direction: str
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Validate ``V``/``F``; for ``direction="normal"`` also the unit normals (Eq. 3.3; a cloud: ``normals`` or PCA normals)."""
    check_choice(direction, "direction", DIRECTIONS)
    V = as_points(V, "V")
    if F is not None:
        F = as_faces(F, V.shape[0], "F")
    N = None
    if direction == "normal":
        if normals is not None:
            N = np.asarray(normals, dtype=np.float64)
            if N.shape != V.shape:
                raise InvalidInputError(f"`normals` must have shape {V.shape}; got {N.shape}.")
            if not np.isfinite(N).all():
                raise InvalidInputError("`normals` contains NaN or inf values.")
            norm = np.linalg.norm(N, axis=1, keepdims=True)
            N = np.divide(N, norm, out=np.zeros_like(N), where=norm > 0)
        elif F is not None:
            N = vertex_normals(V, F)
        else:
            if V.shape[0] < 4:
                raise InvalidInputError(
                    "normal-direction noise on a point cloud needs `normals` or at least 4 points."
                )
            from ..geometry.pointcloud import pca_normals

            N = pca_normals(V, k=min(10, V.shape[0] - 1), orient="none")
    return V, F, N


def directions(
    n: int, N: np.ndarray | None, rng: np.random.Generator, coeff: np.ndarray
) -> np.ndarray:
    """Displacements of per-vertex draws ``coeff``: (n,) along ``N``, else (n, 3) isotropic."""
    if N is not None:
        return coeff[:, None] * N
    return coeff
