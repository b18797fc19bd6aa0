"""Numpy inference of the learned models, and a numpy trainer for the denoise-time autoencoders.

BM3D-CNN shrinkage network per feature class (Eqs. 5.40-5.41): ``h = W1 * x + b1``,
``a_c = sum_r w_cr exp(-(h_c - mu_r)^2 / (2 s^2))``, ``y = W2 * a + b2``; the output is the first
row's centre pixel plus its residual. Only the positions of ``h`` it depends on are evaluated.
Autoencoder (Section 5.1.3): ``y = W2 tanh(W1 x + b1) + b2`` (or linear).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

_ACTS = ("tanh", "linear")


# --------------------------------------------------------------------------- BM3D CNN
def rbf(h: np.ndarray, w: np.ndarray, mu: np.ndarray, s: float) -> np.ndarray:
    """``sum_r w[c, r] exp(-(h_c - mu_r)^2 / (2 s^2))`` on the last axis ``c`` of ``h``."""
    out = np.zeros(np.broadcast_shapes(h.shape, w.shape[:1]), dtype=np.result_type(h, w))
    inv = -0.5 / (s * s)
    for r in range(mu.size):
        out += w[:, r] * np.exp(inv * (h - mu[r]) ** 2)
    return out


class RBFTable:
    """The RBF mixture of Eq. (5.41) per channel, tabulated on ``[mu_0 - 8 s, mu_-1 + 8 s]`` (error about 1e-8)."""

    def __init__(self, w: np.ndarray, mu: np.ndarray, s: float, n: int = 32769):
        self.lo = float(mu[0] - 8 * s)
        hi = float(mu[-1] + 8 * s)
        self.step = (hi - self.lo) / (n - 1)
        grid = self.lo + self.step * np.arange(n)
        tab = rbf(grid[:, None], np.asarray(w, dtype=np.float64), np.asarray(mu), s)  # (n, C)
        self.table = np.ascontiguousarray(tab.T.astype(np.float32))  # (C, n)
        self.n = n

    def __call__(self, h: np.ndarray) -> np.ndarray:
        """``f`` on ``h`` (..., C) float32."""
        C = self.table.shape[0]
        u = (h - np.float32(self.lo)) / np.float32(self.step)
        np.clip(u, 0, self.n - 1.000001, out=u)
        i = u.astype(np.int32)
        frac = u - i
        flat = self.table.ravel()
        base = np.arange(C, dtype=np.int32) * self.n
        j = i + base
        a = flat[j]
        return a + frac * (flat[j + 1] - a)


def cnn_centre(
    x: np.ndarray,
    W1,
    b1,
    rw,
    mu,
    s,
    W2,
    b2,
    *,
    chunk: int = 4096,
    table: RBFTable | None = None,
    index: np.ndarray | None = None,
) -> np.ndarray:
    """Denoised centre pixel (b, 3) of the first row of every image (the network of the module notes).

    ``x`` (b, ch, rows, k) with ``rows >= ks`` and ``k >= 2 ks - 1``; ``W1`` (C, ch, ks, ks), ``b1``,
    ``rw`` (C, R), ``mu``, ``s``, ``W2`` (3, C, ks, ks), ``b2``. With ``table`` one compiled float32
    kernel; without, Eq. (5.41) exactly in float64, ``chunk`` images at a time. ``index`` evaluates
    only ``x[index]``.
    """
    b, ch, rows, k = x.shape
    C, _, ks, _ = W1.shape
    p = ks // 2
    c = k // 2
    if rows < ks or k < 2 * ks - 1:
        raise ValueError(f"images of {rows}x{k} are too small for kernels of size {ks}.")
    if index is not None and table is None:
        return cnn_centre(x[index], W1, b1, rw, mu, s, W2, b2, chunk=chunk)
    if table is not None:  # fused compiled kernel, float32 as the tabulated path
        index = np.arange(b) if index is None else np.asarray(index, dtype=np.int64)
        out = np.empty((index.size, 3), dtype=np.float32)
        W2c = np.ascontiguousarray(W2[:, :, p:, :].transpose(2, 3, 1, 0), dtype=np.float32)
        _centre_kernel(
            np.ascontiguousarray(x[:, :, :ks], dtype=np.float32),
            index,
            c - 2 * p,
            np.ascontiguousarray(np.asarray(W1).transpose(1, 2, 3, 0), dtype=np.float32),
            np.asarray(b1, dtype=np.float32),
            table.table,
            np.float32(table.lo),
            np.float32(table.step),
            W2c,
            np.asarray(b2, dtype=np.float32),
            out,
        )
        return out.astype(np.float64)
    dt = np.float64
    W1m = np.ascontiguousarray(W1.reshape(C, -1).T, dtype=dt)  # (ch ks ks, C)
    W2m = np.ascontiguousarray(W2[:, :, p:, :].transpose(2, 3, 1, 0), dtype=dt).reshape(-1, 3)
    b1 = np.asarray(b1, dtype=dt)
    b2 = np.asarray(b2, dtype=dt)
    out = np.empty((b, 3))
    for s0 in range(0, b, chunk):
        xb = np.asarray(x[s0 : s0 + chunk, :, :ks, c - 2 * p : c + 2 * p + 1], dtype=dt)
        nb = xb.shape[0]
        xp = np.zeros((nb, ch, ks + p, 4 * p + 1), dtype=dt)  # p zero rows above the image
        xp[:, :, p:] = xb
        win = sliding_window_view(xp, (ks, ks), axis=(2, 3))  # (nb, ch, p + 1, ks, ks, ks)
        cols = np.ascontiguousarray(win.transpose(0, 2, 3, 1, 4, 5)).reshape(-1, ch * ks * ks)
        h = (cols @ W1m + b1).reshape(nb, p + 1, ks, C)
        a = table(h) if table is not None else rbf(h, rw, mu, s)
        y = a.reshape(nb, -1) @ W2m + b2
        out[s0 : s0 + nb] = xb[:, :3, 0, 2 * p] + y
    return out


@numba.njit(cache=True, parallel=True, fastmath=True)
def _centre_kernel(x, index, c0, W1t, b1, tab, lo, step, W2c, b2, out):  # pragma: no cover
    """:func:`cnn_centre` with a tabulated shrinkage, fused per image (``out[t]`` for image ``index[t]``)."""
    nb = index.size
    ch = x.shape[1]
    ks = W1t.shape[1]
    C = W1t.shape[3]
    p = ks // 2
    n_tab = tab.shape[1]
    top = np.float32(n_tab - 1.000001)
    for t_ in numba.prange(nb):
        bi = index[t_]
        h = np.empty(C, dtype=np.float32)
        y = np.zeros(3, dtype=np.float32)
        for r in range(p + 1):  # output row r reads image rows r - p .. r + p (zero above 0)
            for q in range(ks):  # output column q reads columns c0 + q .. c0 + q + ks - 1
                for cc in range(C):
                    h[cc] = b1[cc]
                for k in range(ch):
                    for i in range(p - r, ks):
                        row = r + i - p
                        for j in range(ks):
                            v = x[bi, k, row, c0 + q + j]
                            for cc in range(C):
                                h[cc] += W1t[k, i, j, cc] * v
                for cc in range(C):
                    u = (h[cc] - lo) / step
                    u = min(max(u, np.float32(0.0)), top)
                    t = int(u)
                    a = tab[cc, t] + (u - t) * (tab[cc, t + 1] - tab[cc, t])
                    y[0] += a * W2c[r, q, cc, 0]
                    y[1] += a * W2c[r, q, cc, 1]
                    y[2] += a * W2c[r, q, cc, 2]
        cx = c0 + 2 * p
        for o in range(3):
            out[t_, o] = x[bi, o, 0, cx] + y[o] + b2[o]


# --------------------------------------------------------------------------- DAE (MLP)
def mlp_forward(X: np.ndarray, W1, b1, W2, b2, activation: str = "tanh") -> np.ndarray:
    """``W2 act(W1 x + b1) + b2`` for rows ``X`` (b, d); weights stored as (d, H), (H,), (H, d), (d,)."""
    H = X @ W1 + b1
    if activation == "tanh":
        H = np.tanh(H)
    return H @ W2 + b2


def init_mlp(d_in: int, hidden: int, d_out: int, rng) -> dict[str, np.ndarray]:
    """Glorot-uniform weights of a one-hidden-layer autoencoder (float64)."""
    gen = np.random.default_rng(rng)
    lim1 = np.sqrt(6.0 / (d_in + hidden))
    lim2 = np.sqrt(6.0 / (hidden + d_out))
    return {
        "W1": gen.uniform(-lim1, lim1, (d_in, hidden)),
        "b1": np.zeros(hidden),
        "W2": gen.uniform(-lim2, lim2, (hidden, d_out)),
        "b2": np.zeros(d_out),
    }


def train_mlp_numpy(
    X: np.ndarray,
    Y: np.ndarray,
    *,
    hidden: int = 32,
    activation: str = "tanh",
    epochs: int = 20,
    batch_size: int = 256,
    lr: float = 3e-3,
    weight: np.ndarray | None = None,
    rng=0,
    params: dict | None = None,
    min_steps: int = 600,
) -> tuple[dict[str, np.ndarray], list[float]]:
    """Fit ``Y ~ mlp(X)`` by mini-batch Adam on the (column-``weight``-ed) mean squared error, numpy only."""
    if activation not in _ACTS:
        raise ValueError(f"activation must be one of {_ACTS}; got {activation!r}")
    try:  # small matrix products: BLAS threads only add overhead (and oversubscribe)
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        return _train_mlp(
            X, Y, hidden, activation, epochs, batch_size, lr, weight, rng, params, min_steps
        )
    with threadpool_limits(limits=1, user_api="blas"):
        return _train_mlp(
            X, Y, hidden, activation, epochs, batch_size, lr, weight, rng, params, min_steps
        )


def _train_mlp(X, Y, hidden, activation, epochs, batch_size, lr, weight, rng, params, min_steps):
    gen = np.random.default_rng(rng)
    X = np.asarray(X, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    n, d = X.shape
    epochs = max(int(epochs), -(-int(min_steps) // max(1, -(-n // batch_size))))
    p = (
        init_mlp(d, hidden, Y.shape[1], gen)
        if params is None
        else {k: v.copy() for k, v in params.items()}
    )
    w = np.ones(Y.shape[1]) if weight is None else np.asarray(weight, dtype=np.float64)
    m = {k: np.zeros_like(v) for k, v in p.items()}
    v2 = {k: np.zeros_like(v) for k, v in p.items()}
    b1, b2, eps = 0.9, 0.999, 1e-8
    t = 0
    losses = []
    for _ in range(int(epochs)):
        perm = gen.permutation(n)
        tot = 0.0
        for s in range(0, n, batch_size):
            ib = perm[s : s + batch_size]
            xb, yb = X[ib], Y[ib]
            z = xb @ p["W1"] + p["b1"]
            hdn = np.tanh(z) if activation == "tanh" else z
            out = hdn @ p["W2"] + p["b2"]
            r = (out - yb) * w
            tot += float(np.sum(r * (out - yb)))
            g_out = 2.0 * r / (ib.size * Y.shape[1])
            grads = {"W2": hdn.T @ g_out, "b2": g_out.sum(axis=0)}
            g_h = g_out @ p["W2"].T
            if activation == "tanh":
                g_h = g_h * (1.0 - hdn * hdn)
            grads["W1"] = xb.T @ g_h
            grads["b1"] = g_h.sum(axis=0)
            t += 1
            for k in p:
                m[k] = b1 * m[k] + (1 - b1) * grads[k]
                v2[k] = b2 * v2[k] + (1 - b2) * grads[k] ** 2
                mh = m[k] / (1 - b1**t)
                vh = v2[k] / (1 - b2**t)
                p[k] -= lr * mh / (np.sqrt(vh) + eps)
        losses.append(tot / (n * Y.shape[1]))
    return p, losses


__all__ = ["RBFTable", "cnn_centre", "init_mlp", "mlp_forward", "rbf", "train_mlp_numpy"]
