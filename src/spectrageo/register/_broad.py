"""Broad-phase (global) registration, Section 6.2.2 (Eq. 6.24-6.27).

Both clouds are voxel down-sampled to a common voxel ``s``; ``n_samples`` of the most curved
source points are matched to ``n_matches`` target points by curvature descriptors, each match
giving candidate transforms; the density ``rho(T_i) = sum_j exp(-(b d(T_i, T_j))^2)`` (Eq. 6.24)
under the surface metric (Eq. 6.25-6.27) picks peaks, verified by short narrow phases.
Details: docs/decisions.md#register-broad-details.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._errors import InvalidInputError
from .._validation import check_positive
from ._common import WORKERS, bbox_diagonal, make_transform, voxel_downsample, workers_for
from ._narrow import TargetIndex, icp

#: kernel threshold phi of Section 6.2.2 (contributions below phi are neglected)
PHI = 0.01
SCALES = (16, 40)
#: broad-phase voxel: the larger bounding-box diagonal over this (docs/decisions.md#register-defaults)
VOXEL_DIVISOR = 45.0
#: verification: every peak gets VERIFY_SHORT ICP iterations, the VERIFY_KEEP best the rest
#: (docs/decisions.md#register-speed, docs/decisions.md#reg-speed4-verify)
VERIFY_SHORT = 3
VERIFY_KEEP = 3
#: neighbours summed in the density of a candidate (docs/decisions.md#register-speed)
DENSITY_NEIGHBORS = 32
#: a verified pose at least RIVAL_SHARE as fit as the best and RIVAL_DEG degrees away from it is
#: refined too, the finer fit decides (docs/decisions.md#register-rivals)
RIVAL_SHARE = 0.9
RIVAL_DEG = 10.0


def shape_properties(P: np.ndarray, tree: cKDTree, ks=SCALES, chunk: int = 20000):
    """Principal curvatures (n, 2 len(ks)) and frames (n, 3, 3) of every point, by chunks."""
    n = P.shape[0]
    if n > chunk:
        parts = [shape_properties_rows(P, tree, ks, np.arange(i, min(i + chunk, n)))
                 for i in range(0, n, chunk)]  # fmt: skip
        return np.concatenate([a for a, _ in parts]), np.concatenate([b for _, b in parts])
    return shape_properties_rows(P, tree, ks, np.arange(n))


def shape_properties_rows(P: np.ndarray, tree: cKDTree, ks, rows: np.ndarray):
    """:func:`shape_properties` of the points ``P[rows]``.

    One query of the ``max(ks)`` nearest neighbours serves every scale (the ``k`` nearest are
    its first ``k`` columns). At each scale ``k`` the neighbours ``Q`` relative to the point
    give the frame of their covariance (normal: smallest eigenvector, ``u``: largest,
    ``v = n x u``); the height ``z = a x^2 + b x y + c y^2 + d x + e y + f`` is fitted by least
    squares (ridge ``1e-9 trace``) and the principal curvatures ``a + c +- sqrt((a - c)^2 + b^2)``
    (normal flipped to make ``a + c >= 0``) are the descriptor columns; the last scale's
    principal directions and normal form the frame.
    """
    n = P.shape[0]
    kmax = int(min(max(ks), n))
    P0 = P[rows]
    _, idx = tree.query(P0, k=kmax, workers=WORKERS)
    idx = np.asarray(idx).reshape(rows.size, kmax)
    Qmax = P[idx] - P0[:, None, :]
    desc = []
    frame = None
    for to_last, k in enumerate(ks, 1 - len(ks)):
        k = int(min(k, n))
        Q = Qmax if k == kmax else np.ascontiguousarray(Qmax[:, :k])
        Qc = Q - Q.mean(axis=1, keepdims=True)
        _, vec = np.linalg.eigh(np.matmul(Qc.transpose(0, 2, 1), Qc))
        nrm, u = vec[:, :, 0], vec[:, :, 2]
        v = np.cross(nrm, u)
        xyz = np.matmul(Q, np.stack([u, v, nrm], axis=2))  # local coordinates (n, k, 3)
        x, y, z = xyz[:, :, 0], xyz[:, :, 1], xyz[:, :, 2]
        D = np.empty(x.shape + (6,))
        np.multiply(x, x, out=D[:, :, 0])
        np.multiply(x, y, out=D[:, :, 1])
        np.multiply(y, y, out=D[:, :, 2])
        D[:, :, 3] = x
        D[:, :, 4] = y
        D[:, :, 5] = 1.0
        Dt = D.transpose(0, 2, 1)
        A = np.matmul(Dt, D)  # normal equations, batched (n, 6, 6)
        rhs = np.matmul(Dt, z[..., None])
        tr = np.trace(A, axis1=1, axis2=2)[:, None, None]
        A = A + 1e-9 * tr * np.eye(6)
        coef = np.linalg.solve(A, rhs)[..., 0]
        a, b, c = coef[:, 0], coef[:, 1], coef[:, 2]
        flip = a + c < 0  # canonical normal: non-negative mean curvature
        a = np.where(flip, -a, a)
        c = np.where(flip, -c, c)
        diff = np.sqrt((a - c) ** 2 + b * b)
        desc += [a + c + diff, a + c - diff]
        if to_last:  # only the last scale's frame is returned
            continue
        nrm = np.where(flip[:, None], -nrm, nrm)
        v = np.where(flip[:, None], -v, v)
        th = 0.5 * np.arctan2(b, a - c)
        e1 = np.cos(th)[:, None] * u + np.sin(th)[:, None] * v
        e2 = np.cross(nrm, e1)
        frame = np.stack([e1, e2, nrm], axis=2)
    return np.stack(desc, axis=1), frame


def triangle_embedding_basis(P: np.ndarray, tree: cKDTree) -> tuple[np.ndarray, np.ndarray]:
    """Centroid ``c`` and Cholesky factor ``L`` of the source triangles' second moments."""
    n = P.shape[0]
    _, idx = tree.query(P, k=min(3, n), workers=workers_for(n))
    idx = np.asarray(idx).reshape(n, -1)
    if idx.shape[1] < 3:
        c = P.mean(0)
        return c, np.linalg.cholesky(np.cov(P.T) + 1e-12 * np.eye(3))
    a, b, c3 = P[idx[:, 0]], P[idx[:, 1]], P[idx[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c3 - a), axis=1)
    if area.sum() <= 0:
        area = np.ones(n)
    s = a + b + c3
    A = area.sum()
    m1 = (area[:, None] * s / 3.0).sum(0)
    # int_t v v^T da = area / 12 (sum_i v_i v_i^T + s s^T)
    M2 = np.einsum("n,nij->ij", area / 12.0,
                   np.einsum("ni,nj->nij", a, a) + np.einsum("ni,nj->nij", b, b)
                   + np.einsum("ni,nj->nij", c3, c3) + np.einsum("ni,nj->nij", s, s))  # fmt: skip
    cen = m1 / A
    C = M2 / A - np.outer(cen, cen)
    C = 0.5 * (C + C.T) + 1e-12 * np.trace(C) * np.eye(3)
    return cen, np.linalg.cholesky(C)


def embed(R: np.ndarray, t: np.ndarray, cen: np.ndarray, L: np.ndarray) -> np.ndarray:
    """12-vectors ``[vec(R L), R c + t]``: Euclidean for the metric of Eq. 6.25-6.27."""
    RL = (R @ L).reshape(R.shape[0], 9)
    return np.c_[RL, R @ cen + t]


def density(Phi: np.ndarray, radius: float, max_neighbors: int | None = None) -> np.ndarray:
    """``rho`` of Eq. 6.24 at every candidate over at most ``max_neighbors`` within ``radius``."""
    m = Phi.shape[0]
    k = DENSITY_NEIGHBORS if max_neighbors is None else int(max_neighbors)
    b = np.sqrt(-np.log(PHI)) / radius
    # sliding-midpoint tree (faster here than the median split; the same neighbour distances)
    tree = cKDTree(Phi, balanced_tree=False)
    d, _ = tree.query(Phi, k=min(k, m), distance_upper_bound=radius, workers=WORKERS)
    d = np.asarray(d).reshape(m, -1)
    w = np.exp(-((b * d) ** 2))
    w[~np.isfinite(d)] = 0.0
    return w.sum(axis=1)


def _peaks(Phi: np.ndarray, rho: np.ndarray, radius: float, n_peaks: int) -> list[int]:
    """Greedy peaks: the densest candidate, then the densest farther than ``radius`` from every
    chosen one, up to ``n_peaks``."""
    alive = np.ones(Phi.shape[0], dtype=bool)
    score = np.where(np.isfinite(rho), rho, -np.inf)
    peaks: list[int] = []
    while len(peaks) < n_peaks and alive.any():
        i = int(np.argmax(np.where(alive, score, -np.inf)))
        peaks.append(i)
        alive &= np.einsum("ij,ij->i", Phi - Phi[i], Phi - Phi[i]) >= radius * radius
    return peaks


@dataclass(frozen=True, eq=False)
class BroadTarget:
    """Target side of the broad phase at one voxel: points, descriptors, frames, trees."""

    voxel: float
    points: np.ndarray
    desc: np.ndarray
    frames: np.ndarray
    desc_tree: cKDTree
    index: TargetIndex


def broad_target(Tg: np.ndarray, voxel: float) -> BroadTarget:
    """The :class:`BroadTarget` of the cloud ``Tg`` voxel down-sampled at ``voxel``."""
    Tv, _ = voxel_downsample(Tg, voxel)
    if Tv.shape[0] < 6:
        raise InvalidInputError(
            f"`voxel_size` {voxel:.3g} leaves fewer than 6 points ({Tv.shape[0]} target); use a "
            "smaller voxel."
        )
    index = TargetIndex(Tv)
    dt, Ft = shape_properties(Tv, index.tree)
    dt = dt * voxel
    return BroadTarget(voxel, Tv, dt, Ft, cKDTree(dt), index)


def default_voxel(S: np.ndarray, Tg: np.ndarray) -> float:
    """Broad-phase voxel: 1/45 of the larger bounding-box diagonal."""
    diag = max(bbox_diagonal(S), bbox_diagonal(Tg))
    if diag <= 0:
        raise InvalidInputError("`source` and `target` are single points; nothing to register.")
    return diag / VOXEL_DIVISOR


def _verify(Sv, index, R, t, peaks, r, s, verify_iter):
    """Short ICP runs from every peak, the ``VERIFY_KEEP`` best (fitness, then rmse) continued;
    ``(T, fitness, rank, rivals)`` of the best.

    Of the ``VERIFY_KEEP`` best short runs, one that ended at the same pose as a fitter one
    (:func:`_apart` false) is not continued; likewise a rival at the same pose as a fitter rival
    is left out (docs/decisions.md#reg-speed4-verify).
    """

    def run(T0, iters, gamma0):
        return icp(Sv, index, T0, max_iter=int(iters), tol=1e-4, method="point_to_plane",
                   gamma0=gamma0, gamma_min=s, inlier_distance=1.5 * s)  # fmt: skip

    def order(ks):
        return sorted(ks, key=lambda k: (-res[k].fitness, res[k].inlier_rmse, k))

    first = min(VERIFY_SHORT, verify_iter)
    res = [run(make_transform(R[i], t[i]), first, r) for i in peaks]
    ranked = order(range(len(res)))
    if verify_iter > first:
        kept: list[int] = []
        for k in ranked[:VERIFY_KEEP]:
            if all(_apart(res[k].transformation, res[j].transformation, s) for j in kept):
                kept.append(k)
        for k in kept:
            res[k] = run(res[k].transformation, verify_iter - first, res[k].info["gamma"])
        ranked = order(kept)
    k = ranked[0]
    rivals: list[np.ndarray] = []
    for j in ranked[1:VERIFY_KEEP]:
        T = res[j].transformation
        if _rival(res[j], res[k], s) and all(_apart(T, U, s) for U in rivals):
            rivals.append(T)
    return res[k].transformation, res[k].fitness, k, rivals


def _rival(a, best, s: float) -> bool:
    """Whether verified pose ``a`` fits nearly as well as ``best`` (``RIVAL_SHARE``) but is
    another pose (more than ``RIVAL_DEG`` degrees or 3 voxels away)."""
    if a.fitness < RIVAL_SHARE * best.fitness:
        return False
    return _apart(a.transformation, best.transformation, s)


def _apart(A: np.ndarray, B: np.ndarray, s: float) -> bool:
    """Whether the (4, 4) poses ``A`` and ``B`` differ by more than ``RIVAL_DEG`` degrees or
    their relative translation ``A B^-1`` by more than 3 voxels ``s``."""
    D = A @ np.linalg.inv(B)
    ang = np.degrees(np.arccos(np.clip((np.trace(D[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)))
    return bool(ang > RIVAL_DEG or np.linalg.norm(D[:3, 3]) > 3.0 * s)


def broad_phase_points(
    S: np.ndarray,
    Tg: np.ndarray | None,
    *,
    rng: np.random.Generator,
    voxel_size: float | None = None,
    n_samples: int = 400,
    n_matches: int = 10,
    kernel_radius: float | None = None,
    n_peaks: int = 15,
    verify_iter: int = 20,
    target: BroadTarget | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Broad phase on validated point arrays (``target`` reuses a prepared target side and
    fixes the voxel); returns ``(T, info)``."""
    t0 = time.perf_counter()
    check_positive(n_samples, "n_samples", integer=True)
    check_positive(n_matches, "n_matches", integer=True)
    check_positive(n_peaks, "n_peaks", integer=True)
    check_positive(verify_iter, "verify_iter", integer=True, allow_zero=True)
    if target is not None:
        s = target.voxel
    else:
        s = float(voxel_size) if voxel_size is not None else default_voxel(S, Tg)
    check_positive(s, "voxel_size")
    r = float(kernel_radius) if kernel_radius is not None else 3.0 * s
    check_positive(r, "kernel_radius")
    Sv, _ = voxel_downsample(S, s)
    if Sv.shape[0] < 6:
        raise InvalidInputError(
            f"`voxel_size` {s:.3g} leaves fewer than 6 points ({Sv.shape[0]} source); use a "
            "smaller voxel."
        )
    bt = target if target is not None else broad_target(Tg, s)
    Tv, Ft = bt.points, bt.frames
    s_tree = cKDTree(Sv)
    ds, Fs = shape_properties(Sv, s_tree)
    ds = ds * s
    # distinctive source points: the 60 % most curved (curvedness at the larger scale)
    curv = np.hypot(ds[:, -2], ds[:, -1])
    pool = np.flatnonzero(curv >= np.quantile(curv, 0.4))
    pick = np.sort(rng.choice(pool, size=min(int(n_samples), pool.size), replace=False))
    km = int(min(n_matches, Tv.shape[0]))
    _, nb = bt.desc_tree.query(ds[pick], k=km, workers=workers_for(pick.size))
    nb = np.asarray(nb).reshape(pick.size, km)
    si = np.repeat(pick, km)
    ti = nb.ravel()
    flip = np.diag([-1.0, -1.0, 1.0])
    R1 = Ft[ti] @ np.transpose(Fs[si], (0, 2, 1))
    R2 = Ft[ti] @ flip @ np.transpose(Fs[si], (0, 2, 1))
    R = np.concatenate([R1, R2])
    ps = np.concatenate([Sv[si], Sv[si]])
    pt = np.concatenate([Tv[ti], Tv[ti]])
    t = pt - np.einsum("mij,mj->mi", R, ps)
    cen, L = triangle_embedding_basis(Sv, s_tree)
    Phi = np.ascontiguousarray(embed(R, t, cen, L))
    rho = density(Phi, r)
    peaks = _peaks(Phi, rho, r, int(n_peaks))
    best_T = make_transform(R[peaks[0]], t[peaks[0]])
    info: dict[str, Any] = {"n_candidates": int(R.shape[0]), "voxel_size": s, "n_peaks": len(peaks)}
    if verify_iter > 0 and len(peaks) > 1:
        best_T, fit, rank, rivals = _verify(Sv, bt.index, R, t, peaks, r, s, int(verify_iter))
        info["rivals"] = rivals
        info["peak_rank"] = rank
        info["broad_fitness"] = fit
    info["broad_time_s"] = time.perf_counter() - t0
    return best_T, info
