"""Synthetic noise on meshes and point clouds, with ground truth (Sections 3.4, 4.10).

Every function returns a :class:`NoiseResult` (noisy ``vertices``, the exact ``displacement``, the
``mask`` of selected vertices and the per-vertex absolute ``scale``); :func:`apply` is the
convenience dispatcher that returns only the noisy positions.

Noise level convention (Eq. 4.36): ``level`` is relative to the mean edge length ``l`` of the input
mesh, so the absolute scale is ``sigma = level * l``; for point clouds (``F`` None) ``l`` is the mean
distance of a point to its nearest neighbour. Normal-direction noise moves each vertex along its unit
vertex normal (Eq. 3.3), as in the benchmark data of Zhang et al.; ``direction="random"`` draws an
isotropic 3-D vector instead (Eq. 3.10 with independent coordinates).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from .._validation import as_rng, check_choice
from ._core import NoiseResult, check_fraction, check_level, mean_spacing, prepare


def _draw(
    kind: str, rng: np.random.Generator, n: int, along_normal: bool, sigma: np.ndarray
) -> np.ndarray:
    """Per-vertex draws with standard deviation ``sigma`` (n,): shape (n,) or (n, 3)."""
    shape = (n,) if along_normal else (n, 3)
    s = sigma if along_normal else sigma[:, None]
    if kind == "gaussian":
        return rng.standard_normal(shape) * s
    # uniform with the same standard deviation: half-width sqrt(3) * sigma
    return rng.uniform(-1.0, 1.0, shape) * (np.sqrt(3.0) * s)


def _dense(kind, V, F, level, rng, direction, normals) -> NoiseResult:
    level = check_level(level)
    V, F, N = prepare(V, F, normals, direction)
    rng = as_rng(rng)
    n = V.shape[0]
    sigma = np.full(n, level * mean_spacing(V, F))
    c = _draw(kind, rng, n, N is not None, sigma)
    D = c[:, None] * N if N is not None else c
    return NoiseResult(V + D, D, np.ones(n, dtype=bool), sigma, None, kind)


def gaussian(
    V, F=None, *, level: float, rng=None, direction: str = "normal", normals=None
) -> NoiseResult:
    """Zero-mean Gaussian noise with standard deviation ``sigma = level * l`` (Eq. 4.36, 3.10).

    Parameters
    ----------
    V : (n, 3) array_like
        Clean vertices (or points).
    F : (m, 3) array_like of int or None
        Faces; None for a point cloud (then ``l`` is the mean nearest-neighbour distance and normals
        are ``normals`` or PCA normals).
    level : float
        ``sigma_E`` of Eq. (4.36), >= 0.
    rng : int, Generator or None
        Seed or generator (None = seed 0).
    direction : {"normal", "random"}
        ``"normal"``: scalar N(0, sigma) along the unit vertex normal (the displacement's component
        along the normal has standard deviation ``sigma``); ``"random"``: isotropic, each coordinate
        N(0, sigma).
    normals : (n, 3) array_like, optional
        Directions to use instead of the computed normals (normalised here).

    Returns
    -------
    NoiseResult
    """
    return _dense("gaussian", V, F, level, rng, direction, normals)


def uniform(
    V, F=None, *, level: float, rng=None, direction: str = "normal", normals=None
) -> NoiseResult:
    """Zero-mean uniform noise with the same standard deviation as :func:`gaussian`.

    Draws from U(-a, a) with half-width ``a = sqrt(3) * level * l`` (standard deviation
    ``level * l``), along the normals or, with ``direction="random"``, independently per coordinate.
    """
    return _dense("uniform", V, F, level, rng, direction, normals)


def impulsive(
    V,
    F=None,
    *,
    fraction: float = 0.1,
    level: float,
    rng=None,
    direction: str = "normal",
    normals=None,
) -> NoiseResult:
    """Impulsive noise: a random subset of ``round(fraction * n)`` vertices (without replacement)
    gets Gaussian noise of standard deviation ``level * l``; the others are unchanged.

    ``mask`` marks the chosen vertices. Parameters as in :func:`gaussian`.
    """
    fraction = check_fraction(fraction)
    level = check_level(level)
    V, F, N = prepare(V, F, normals, direction)
    rng = as_rng(rng)
    n = V.shape[0]
    sigma0 = level * mean_spacing(V, F)
    k = int(round(fraction * n))
    idx = rng.choice(n, size=k, replace=False)
    mask = np.zeros(n, dtype=bool)
    mask[idx] = True
    sigma = np.where(mask, sigma0, 0.0)
    D = np.zeros_like(V)
    if N is not None:
        D[idx] = rng.standard_normal(k)[:, None] * sigma0 * N[idx]
    else:
        D[idx] = rng.standard_normal((k, 3)) * sigma0
    return NoiseResult(V + D, D, mask, sigma, None, "impulsive")


def _farthest_points(V: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    first = int(rng.integers(V.shape[0]))
    seeds = [first]
    d = np.linalg.norm(V - V[first], axis=1)
    for _ in range(k - 1):
        nxt = int(np.argmax(d))
        seeds.append(nxt)
        d = np.minimum(d, np.linalg.norm(V - V[nxt], axis=1))
    return np.asarray(seeds)


def region_varying(
    V,
    F=None,
    *,
    levels=(0.1, 0.3, 0.5, 0.7),
    mode: str = "clusters",
    kind: str = "gaussian",
    rng=None,
    direction: str = "normal",
    normals=None,
) -> NoiseResult:
    """Noise whose level varies over the surface (complex noise patterns, Section 3.4 item 8).

    ``mode="clusters"``: ``len(levels)`` regions are formed around seed vertices chosen by farthest
    point sampling from a random start; every vertex joins its nearest seed (Euclidean), and region
    ``r`` gets ``levels[r]``. ``labels`` holds the region of every vertex.

    ``mode="smooth"``: ``levels`` must be ``(low, high)``; the level ramps linearly along a random
    unit direction ``u``: ``level(v) = low + (high - low) * (u.v - min) / (max - min)``.

    The absolute scale is ``level(v) * l`` (Eq. 4.36) and the noise is ``kind`` ("gaussian" or
    "uniform", same standard deviation) along ``direction``.
    """
    check_choice(mode, "mode", ("clusters", "smooth"))
    check_choice(kind, "kind", ("gaussian", "uniform"))
    lv = np.atleast_1d(np.asarray(levels, dtype=np.float64))
    if lv.ndim != 1 or lv.size == 0:
        raise InvalidInputError(f"`levels` must be a 1-D sequence of levels; got shape {lv.shape}.")
    for x in lv:
        check_level(float(x), "levels")
    if mode == "smooth" and lv.size != 2:
        raise InvalidInputError(
            f"`levels` must be (low, high) for mode='smooth'; got {lv.size} values."
        )
    V, F, N = prepare(V, F, normals, direction)
    rng = as_rng(rng)
    n = V.shape[0]
    l_mean = mean_spacing(V, F)
    if mode == "clusters":
        if lv.size > n:
            raise InvalidInputError(
                f"`levels` has {lv.size} regions but there are only {n} vertices."
            )
        seeds = _farthest_points(V, lv.size, rng)
        labels = cKDTree(V[seeds]).query(V)[1].astype(np.int64)
        level_v = lv[labels]
    else:
        u = rng.standard_normal(3)
        u /= np.linalg.norm(u)
        p = V @ u
        span = p.max() - p.min()
        t = (p - p.min()) / span if span > 0 else np.zeros(n)
        level_v = lv[0] + (lv[1] - lv[0]) * t
        labels = None
    sigma = level_v * l_mean
    c = _draw(kind, rng, n, N is not None, sigma)
    D = c[:, None] * N if N is not None else c
    return NoiseResult(V + D, D, np.ones(n, dtype=bool), sigma, labels, "region_varying")


def anisotropic(
    V,
    F=None,
    *,
    level: float,
    ratio: float = 0.25,
    frame: str = "axis",
    axis=None,
    rng=None,
    normals=None,
) -> NoiseResult:
    """Anisotropic Gaussian noise: standard deviation ``sigma = level * l`` (Eq. 4.36) along one
    principal direction and ``ratio * sigma`` across it.

    ``frame="axis"``: the principal direction is one unit vector ``u`` for the whole object
    (``axis``, else drawn at random from ``rng``), like the depth noise of a range scanner along its
    viewing direction; the displacement covariance is ``sigma^2 (u u^T + ratio^2 (I - u u^T))``.
    ``frame="normal"``: the principal direction is the unit vertex normal (Eq. 3.3) and the
    tangential components get ``ratio * sigma`` (vertices without a normal are not moved).

    Parameters
    ----------
    V : (n, 3) array_like
    F : (m, 3) array_like of int or None
        None for a point cloud (``l`` is then the mean nearest-neighbour distance).
    level : float
        ``sigma_E`` of Eq. (4.36) along the principal direction, >= 0.
    ratio : float
        Standard deviation across the principal direction relative to ``sigma``, >= 0.
    frame : {"axis", "normal"}
    axis : (3,) array_like, optional
        The principal direction for ``frame="axis"`` (normalised here).
    rng : int, Generator or None
    normals : (n, 3) array_like, optional
        Directions to use instead of the computed normals for ``frame="normal"``.

    Returns
    -------
    NoiseResult
        ``scale`` is ``sigma`` (the principal standard deviation) for every vertex.
    """
    level = check_level(level)
    ratio = check_level(ratio, "ratio")
    check_choice(frame, "frame", ("axis", "normal"))
    if axis is not None and frame != "axis":
        raise InvalidInputError(f"`axis` applies to frame='axis' only; got frame={frame!r}.")
    V, F, N = prepare(V, F, normals, "normal" if frame == "normal" else "random")
    rng = as_rng(rng)
    n = V.shape[0]
    sigma = level * mean_spacing(V, F)
    if frame == "axis":
        if axis is None:
            u = rng.standard_normal(3)
        else:
            u = np.asarray(axis, dtype=np.float64).reshape(-1)
            if u.shape != (3,) or not np.isfinite(u).all() or not np.linalg.norm(u) > 0:
                raise InvalidInputError(
                    f"`axis` must be a finite non-zero 3-vector; got {np.asarray(axis)!r}."
                )
        u = u / np.linalg.norm(u)
        A = (np.eye(3) - np.outer(u, u)) * ratio + np.outer(u, u)  # symmetric square root
        D = rng.standard_normal((n, 3)) @ A * sigma
    else:
        # per-vertex tangent frame (T1, T2) orthogonal to N; zero where N is zero
        ref = np.where(np.abs(N[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        T1 = np.cross(N, ref)
        nt = np.linalg.norm(T1, axis=1, keepdims=True)
        T1 = np.divide(T1, nt, out=np.zeros_like(T1), where=nt > 0)
        T2 = np.cross(N, T1)
        z = rng.standard_normal((n, 3)) * sigma
        D = z[:, :1] * N + ratio * (z[:, 1:2] * T1 + z[:, 2:] * T2)
    return NoiseResult(V + D, D, np.ones(n, dtype=bool), np.full(n, sigma), None, "anisotropic")


def quantize(V, F=None, *, level: float) -> NoiseResult:
    """Quantisation noise: coordinates rounded to a grid of step ``q = level * l`` anchored at the
    origin (``q * round(v / q)``), e.g. to mimic a coarse coordinate encoding. Deterministic.

    ``level = 0`` leaves the vertices unchanged. ``scale`` is ``q`` for every vertex.
    """
    level = check_level(level)
    V, F, _ = prepare(V, F, None, "random")
    q = level * mean_spacing(V, F)
    Vq = np.round(V / q) * q if q > 0 else V.copy()
    D = Vq - V
    return NoiseResult(
        Vq, D, np.ones(V.shape[0], dtype=bool), np.full(V.shape[0], q), None, "quantization"
    )


KINDS = ("gaussian", "uniform", "impulsive", "quantization", "quantisation")


def apply(
    V,
    F=None,
    *,
    kind: str = "gaussian",
    level: float = 0.3,
    rng=None,
    fraction: float | None = None,
    direction: str = "normal",
    normals=None,
    return_result: bool = False,
):
    """Add noise of one ``kind`` and return the noisy vertices (n, 3) (or the full NoiseResult).

    Parameters
    ----------
    V : (n, 3) array_like
    F : (m, 3) array_like of int or None
        None for a point cloud.
    kind : {"gaussian", "uniform", "impulsive", "quantization" ("quantisation")}
    level : float
        Relative level (Eq. 4.36): standard deviation (gaussian, uniform, impulsive) or grid step
        (quantization) divided by the mean edge length.
    rng : int, Generator or None
    fraction : float, optional
        Fraction of vertices hit by impulsive noise (default 0.1); only for ``kind="impulsive"``.
    direction : {"normal", "random"}
    normals : (n, 3) array_like, optional
    return_result : bool
        Return the :class:`NoiseResult` (with the ground-truth displacement) instead of the array.
    """
    check_choice(kind, "kind", KINDS)
    if fraction is not None and kind != "impulsive":
        raise InvalidInputError(
            f"`fraction` applies to kind='impulsive' only; got fraction={fraction!r} with kind={kind!r}."
        )
    if kind in ("gaussian", "uniform"):
        res = _dense(kind, V, F, level, rng, direction, normals)
    elif kind == "impulsive":
        res = impulsive(
            V,
            F,
            fraction=0.1 if fraction is None else fraction,
            level=level,
            rng=rng,
            direction=direction,
            normals=normals,
        )
    else:
        res = quantize(V, F, level=level)
    return res if return_result else res.vertices
