"""Noise on meshes and point clouds with ground truth (Sections 3.4, 4.10).

``sigma = level * l`` (Eq. 4.36), ``l`` the mean edge length (a cloud: the nearest-neighbour
distance); ``direction="normal"`` moves along the unit vertex normal (Eq. 3.3),
``"random"`` draws an isotropic vector (Eq. 3.10).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from .._validation import as_rng, check_choice, deprecated_flag
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
    """Zero-mean Gaussian noise of standard deviation ``level * l`` (Eqs. 3.10, 4.36).

    ``F`` None for a point cloud; ``direction`` "normal" (along the unit vertex normals, or the
    given ``normals``) or "random" (isotropic). Returns a :class:`NoiseResult`.
    """
    return _dense("gaussian", V, F, level, rng, direction, normals)


def uniform(
    V, F=None, *, level: float, rng=None, direction: str = "normal", normals=None
) -> NoiseResult:
    """Zero-mean uniform noise on ``[-sqrt(3) level l, sqrt(3) level l]``; parameters as :func:`gaussian`."""
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
    """Gaussian noise on ``round(fraction * n)`` random vertices (``mask``); parameters as :func:`gaussian`."""
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
    """Noise whose level varies over the surface (Section 3.4, item 8).

    ``mode="clusters"``: regions around farthest-point seeds, region ``r`` at ``levels[r]``
    (``labels``); ``mode="smooth"``: ``levels=(low, high)`` ramped along a random direction.
    ``kind`` is "gaussian" or "uniform".
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
    """Gaussian noise of deviation ``level * l`` along one direction and ``ratio`` times that across it.

    ``frame="axis"``: one direction ``axis`` (default random) for the whole object, like a range
    scanner's depth noise; ``frame="normal"``: along each unit vertex normal.
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
    """Coordinates rounded to the grid of step ``level * l`` (deterministic; ``scale`` is the step)."""
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
    return_result: bool | None = None,
):
    """Noise of one ``kind`` (gaussian, uniform, impulsive, quantization); returns the noisy (n, 3) vertices.

    ``fraction`` (default 0.1) is for ``"impulsive"`` only. :func:`apply_result` returns the
    :class:`NoiseResult` (``return_result`` is deprecated).
    """
    if return_result is not None:
        deprecated_flag("apply", "return_result", "apply_result() (the NoiseResult)")
    res = apply_result(
        V, F, kind=kind, level=level, rng=rng, fraction=fraction, direction=direction,
        normals=normals,
    )  # fmt: skip
    return res if return_result else res.vertices


def apply_result(
    V,
    F=None,
    *,
    kind: str = "gaussian",
    level: float = 0.3,
    rng=None,
    fraction: float | None = None,
    direction: str = "normal",
    normals=None,
) -> NoiseResult:
    """:func:`apply` returning the :class:`NoiseResult` (noisy vertices and ground truth)."""
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
    return res
