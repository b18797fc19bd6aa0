"""PyTorch path of the patch RPCA of :func:`spectrageo.outliers.rpca_scores`.

The iteration of :func:`._kernels.patch_ialm_pass` (Eq. 4.22 on the patch matrix of Eq. 5.98) as
dense tensor operations on any torch device: the gathered ``M``, the state ``R``, the elementwise
steps, ``E = X W`` and the float64 Gram matrix and residual run on the device; the ``K x K``
eigendecomposition (:func:`._svt.svt_operator`, shared with the numba path), the ``mu`` schedule
and the stopping rules on the host. Per iteration about ``4 K^2`` numbers cross. Float32
products run with TF32 disabled (it would round ``X W`` to 10-bit mantissas).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import numpy as np

__all__ = ["patch_ialm_torch", "torch_threads"]

#: Points per chunk of the elementwise steps (bounds the temporaries: about 140 bytes per
#: point and column in float32, i.e. 400 MB for K = 11).
CHUNK = 262_144


@contextlib.contextmanager
def _no_tf32(torch: Any) -> Iterator[None]:
    """Full float32 precision of matrix products on CUDA while the solver runs."""
    cuda_flag = torch.backends.cuda.matmul.allow_tf32
    prec = torch.get_float32_matmul_precision()
    try:
        torch.backends.cuda.matmul.allow_tf32 = False
        torch.set_float32_matmul_precision("highest")
        yield
    finally:
        torch.backends.cuda.matmul.allow_tf32 = cuda_flag
        torch.set_float32_matmul_precision(prec)


@contextlib.contextmanager
def torch_threads(device: Any, workers: int | None) -> Iterator[None]:
    """Limit torch's intra-op threads to ``workers`` (> 0) on the CPU device; else no change."""
    import torch

    if torch.device(device).type != "cpu" or workers is None or workers < 0:
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(max(1, int(workers)))
    try:
        yield
    finally:
        torch.set_num_threads(before)


def patch_ialm_torch(
    Pn: np.ndarray,
    centers: np.ndarray,
    nbrs: np.ndarray,
    lam: float | None,
    rho: float,
    tol: float,
    rank_tol: float,
    max_iter: int,
    want_e0: bool,
    vec: np.ndarray,
    device: Any,
    record: list | None = None,
) -> tuple[np.ndarray, np.ndarray | None, int, bool, float]:
    """:func:`._rpca_solver.patch_ialm` on the torch device ``device`` (same arguments and returns).

    ``Pn`` (n, 3) float32 or float64: the normalised cloud (the dtype of the state); ``centers``
    (m,) and ``nbrs`` (m, k): the rows of the block's patch matrix. Returns ``(scores, E0,
    n_iter, converged, residual)`` and writes the first-column residual vectors into ``vec``
    ((m, 3), or no rows). Same ``mu`` schedule, ``rho``, ``lam`` and stopping rules (``tol``
    and the ranking rule ``rank_tol``) as the numba kernel.
    """
    import torch

    from ._svt import RANK_BIN, RANK_FLOOR, svt_operator

    dev = torch.device(device)
    m = int(centers.shape[0])
    K = int(nbrs.shape[1]) + 1
    np_dt = Pn.dtype.type
    tdt = torch.float32 if Pn.dtype == np.float32 else torch.float64
    f64 = torch.float64
    want_v = vec.shape[0] > 0

    with _no_tf32(torch), torch.no_grad():
        P_t = torch.from_numpy(np.ascontiguousarray(Pn)).to(dev)
        cols = torch.empty((m, K), dtype=torch.int64, device=dev)
        cols[:, 0] = torch.from_numpy(np.ascontiguousarray(centers)).to(dev)
        cols[:, 1:] = torch.from_numpy(np.ascontiguousarray(nbrs)).to(dev)
        # rows 3r + c of M: coordinate c of the point and of its k neighbours (Eq. 5.98)
        M = P_t[cols].transpose(1, 2).reshape(3 * m, K).contiguous()
        del cols, P_t
        bounds = [(3 * a, 3 * min(m, a + CHUNK)) for a in range(0, m, CHUNK)]

        G_t = torch.zeros((K, K), dtype=f64, device=dev)
        for a, b in bounds:
            Md = M[a:b].to(f64)
            G_t += Md.T @ Md
        G = G_t.cpu().numpy().copy()  # not a view of G_t (reused below; recorded steps)
        fro = float(np.sqrt(max(np.trace(G), 0.0)))
        if fro == 0.0:
            if want_v:
                vec[:] = 0.0
            return np.zeros(m), (np.zeros((m, 3)) if want_e0 else None), 0, True, 0.0

        lam = 1.0 / np.sqrt(3.0 * m) if lam is None else float(lam)
        s_max = float(np.sqrt(max(np.linalg.eigvalsh(G)[-1], 0.0)))
        mu = 1.25 / s_max
        mu_max = mu * 1e7
        mu_prev = mu
        R = torch.zeros((3 * m, K), dtype=tdt, device=dev)
        scores = torch.zeros(m, dtype=f64, device=dev)
        E0 = torch.zeros((m, 3), dtype=f64, device=dev) if want_e0 else None
        V0 = torch.zeros((m, 3), dtype=tdt, device=dev) if want_v else None
        bins = torch.full((m,), -2, dtype=torch.int32, device=dev)
        converged, residual, it = False, np.inf, 0
        inv_width = 1.0 / RANK_BIN
        for it in range(1, max_iter + 1):  # noqa: B007 - `it` is returned
            ops = [x.astype(np_dt) for x in svt_operator(G, 1.0 / mu)]
            W, A, B = (torch.from_numpy(x).to(dev) for x in ops)
            low = 2 * A.shape[1] < K
            mu_next = min(mu * rho, mu_max)
            # the scalars rounded to the state's dtype, as in the numba kernel
            scal = (
                np_dt(lam / mu_prev),
                np_dt(mu_prev / mu),
                np_dt(lam / mu),
                np_dt(1.0 + mu / mu_next),
            )
            if record is not None:  # the same step as :func:`._rpca_solver.patch_ialm` records
                record.append((G, mu, (*ops, *scal)))
            tp, fp, t, f1 = (float(x) for x in scal)
            G_t.zero_()
            res2 = torch.zeros((), dtype=f64, device=dev)
            for a, b in bounds:
                Mc, Rc = M[a:b], R[a:b]
                cl = Rc.clamp(-tp, tp)
                Y = cl * fp
                X = Mc - Rc + cl + Y
                E = (X @ A) @ B if low else X @ W
                Rn = Mc - E + Y
                Rc.copy_(Rn)
                cl = Rn.clamp(-t, t)
                z = (cl - Y).to(f64)
                res2 += (z * z).sum()
                Xn = (Mc - Rn + f1 * cl).to(f64)  # the next SVT argument
                G_t += Xn.T @ Xn
                p0, p1 = a // 3, b // 3
                sv = (Rn - cl).view(-1, 3, K)[:, :, 0]
                scores[p0:p1] = sv.to(f64).square().sum(dim=1).sqrt()
                if V0 is not None:
                    V0[p0:p1] = sv
                if E0 is not None:
                    E0[p0:p1] = E.view(-1, 3, K)[:, :, 0].to(f64)
                del cl, Y, X, E, Rn, z, Xn, sv
            if rank_tol > 0:
                lv = torch.floor(torch.log10(scores / RANK_FLOOR) * inv_width)
                nb = torch.where(scores >= RANK_FLOOR, lv, torch.full_like(lv, -1.0)).to(
                    torch.int32
                )
                changed = (nb != bins).sum().to(f64).reshape(1)
                bins = nb
            else:
                changed = torch.zeros(1, dtype=f64, device=dev)
            host = torch.cat([G_t.reshape(-1), res2.reshape(1), changed]).cpu().numpy()
            G = host[: K * K].reshape(K, K).copy()
            residual = float(np.sqrt(host[K * K])) / fro
            n_changed = int(host[K * K + 1])
            mu_prev, mu = mu, mu_next
            if residual <= tol:
                converged = True
                break
            if (
                rank_tol > 0
                and it > 1
                and lam / mu_prev <= RANK_FLOOR
                and (n_changed <= rank_tol * m)
            ):
                converged = True
                break
        scores_h = scores.cpu().numpy()
        if V0 is not None:
            vec[:] = V0.cpu().numpy()
        E0_h = E0.cpu().numpy() if E0 is not None else None
    return scores_h, E0_h, it, converged, residual
