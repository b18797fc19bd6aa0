"""PyTorch definitions of the learned models (training only; inference is numpy, see ``_nn``).

Imported lazily by :mod:`spectrageo.learn.train`; needs the ``learn`` extra (``torch``).
The modules compute exactly what :func:`spectrageo.learn._nn.cnn_centre` and
:func:`spectrageo.learn._nn.mlp_forward` compute, so exported weights give the same outputs.
"""

from __future__ import annotations

import numpy as np

try:
    import torch
    from torch import nn
    from torch.nn import functional as tF
except ImportError as exc:  # pragma: no cover - exercised without torch
    raise ImportError("training needs PyTorch: install spectrageo[learn]") from exc


def setup(seed: int, *, device: str = "cpu", threads: int | None = None) -> torch.device:
    """Seed torch, ask for deterministic algorithms, optionally cap the CPU threads; returns the
    device (``"cuda"`` only when asked and available)."""
    torch.manual_seed(int(seed))
    torch.use_deterministic_algorithms(True, warn_only=True)
    if threads is not None:
        torch.set_num_threads(int(threads))
    if device == "cuda":
        if not torch.cuda.is_available():
            raise RuntimeError("`device` 'cuda' was asked for but no CUDA device is available.")
        torch.backends.cudnn.deterministic = True
        torch.backends.cudnn.benchmark = False
        return torch.device("cuda")
    return torch.device("cpu")


def _identity_rbf(mu: np.ndarray, s: float) -> np.ndarray:
    """RBF mixture weights (R,) that best reproduce ``f(h) = h`` on ``[mu_0, mu_-1]`` (init)."""
    h = np.linspace(mu[0], mu[-1], 200)
    Phi = np.exp(-((h[:, None] - mu[None]) ** 2) / (2 * s * s))
    return np.linalg.lstsq(Phi, h, rcond=None)[0]


class ShrinkageCNN(nn.Module):
    """Per-class network of Eq. (5.40)-(5.41), output = centre pixel of the first row."""

    def __init__(self, n_classes=3, channels=6, width=16, kernel=5, n_rbf=9, rbf_range=2.0):
        super().__init__()
        self.kernel = kernel
        mu = np.linspace(-rbf_range, rbf_range, n_rbf)
        self.s = float(mu[1] - mu[0]) if n_rbf > 1 else 1.0
        self.register_buffer("mu", torch.tensor(mu, dtype=torch.float32))
        fan = channels * kernel * kernel
        self.W1 = nn.Parameter(
            torch.randn(n_classes, width, channels, kernel, kernel) / np.sqrt(fan)
        )
        self.b1 = nn.Parameter(torch.zeros(n_classes, width))
        rw = np.tile(_identity_rbf(mu, self.s), (n_classes, width, 1))
        self.rw = nn.Parameter(torch.tensor(rw, dtype=torch.float32))
        self.W2 = nn.Parameter(
            1e-3
            * torch.randn(n_classes, 3, width, kernel, kernel)
            / np.sqrt(width * kernel * kernel)
        )
        self.b2 = nn.Parameter(torch.zeros(n_classes, 3))

    def forward_class(self, x: torch.Tensor, c: int) -> torch.Tensor:
        p = self.kernel // 2
        k = x.shape[-1]
        kc = k // 2
        # only the (p + 1) x ks positions of h that reach the output: zero rows above the image
        # ("same" padding), no column padding, columns kc - 2p .. kc + 2p of the input
        xs = tF.pad(x[:, :, : self.kernel, kc - 2 * p : kc + 2 * p + 1], (0, 0, p, 0))
        h = tF.conv2d(xs, self.W1[c], self.b1[c])
        d = h.unsqueeze(-1) - self.mu
        a = (torch.exp(-(d * d) / (2 * self.s * self.s)) * self.rw[c][:, None, None, :]).sum(-1)
        y = torch.einsum("bcrq,ocrq->bo", a, self.W2[c][:, :, p:, :]) + self.b2[c]
        return x[:, :3, 0, kc] + y

    def forward(self, x: torch.Tensor, cls: torch.Tensor) -> torch.Tensor:
        out = torch.zeros(x.shape[0], 3, dtype=x.dtype, device=x.device)
        for c in range(self.W1.shape[0]):
            sel = torch.nonzero(cls == c).flatten()
            if sel.numel():
                out = out.index_copy(0, sel, self.forward_class(x[sel], c))
        return out

    def export(self) -> dict[str, np.ndarray]:
        g = {k: v.detach().cpu().double().numpy() for k, v in self.named_parameters()}
        g["mu"] = self.mu.detach().cpu().double().numpy()
        return g


class ContentDAE(nn.Module):
    """Content-wise denoising autoencoders (Section 5.1.3): one one-hidden-layer autoencoder per
    content group, ``y = W2 act(W1 x + b1) + b2`` with row-vector weights (d, H), (H, d)."""

    def __init__(self, n_models: int, d: int, hidden: int = 32, activation: str = "tanh"):
        super().__init__()
        self.activation = activation
        lim1 = np.sqrt(6.0 / (d + hidden))
        self.W1 = nn.Parameter((torch.rand(n_models, d, hidden) * 2 - 1) * lim1)
        self.b1 = nn.Parameter(torch.zeros(n_models, hidden))
        self.W2 = nn.Parameter((torch.rand(n_models, hidden, d) * 2 - 1) * lim1)
        self.b2 = nn.Parameter(torch.zeros(n_models, d))

    def forward_model(self, x: torch.Tensor, j: int) -> torch.Tensor:
        h = x @ self.W1[j] + self.b1[j]
        if self.activation == "tanh":
            h = torch.tanh(h)
        return h @ self.W2[j] + self.b2[j]

    def forward(self, x: torch.Tensor, model: torch.Tensor) -> torch.Tensor:
        out = torch.zeros(x.shape[0], self.W2.shape[-1], dtype=x.dtype, device=x.device)
        for j in range(self.W1.shape[0]):
            sel = torch.nonzero(model == j).flatten()
            if sel.numel():
                out = out.index_copy(0, sel, self.forward_model(x[sel], j))
        return out

    def export(self) -> dict[str, np.ndarray]:
        return {k: v.detach().cpu().double().numpy() for k, v in self.named_parameters()}


def fit(
    net: nn.Module,
    X: np.ndarray,
    groups: np.ndarray,
    Y: np.ndarray,
    *,
    epochs: int,
    device,
    batch_size: int = 512,
    lr: float = 3e-3,
    seed: int = 0,
    val: tuple | None = None,
    log=None,
) -> dict[str, list[float]]:
    """Adam on the mean squared error with a cosine learning-rate decay; returns the per-epoch
    training (and validation, when ``val=(X, groups, Y)``) losses."""
    net.to(device)
    Xt = torch.tensor(X, dtype=torch.float32)
    Gt = torch.tensor(groups, dtype=torch.int64)
    Yt = torch.tensor(Y, dtype=torch.float32)
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    n = Xt.shape[0]
    steps = max(1, epochs * ((n + batch_size - 1) // batch_size))
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=steps, eta_min=lr * 0.05)
    gen = torch.Generator().manual_seed(int(seed))
    hist = {"train": [], "val": []}
    for ep in range(int(epochs)):
        net.train()
        perm = torch.randperm(n, generator=gen)
        tot = 0.0
        for s in range(0, n, batch_size):
            ib = perm[s : s + batch_size]
            xb, gb, yb = Xt[ib].to(device), Gt[ib].to(device), Yt[ib].to(device)
            loss = ((net(xb, gb) - yb) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            tot += float(loss.detach()) * ib.numel()
        hist["train"].append(tot / n)
        if val is not None:
            hist["val"].append(evaluate_loss(net, *val, device=device))
        if log is not None:
            v = f", val {hist['val'][-1]:.5f}" if val is not None else ""
            log(f"epoch {ep + 1}/{epochs}: train {hist['train'][-1]:.5f}{v}")
    return hist


@torch.no_grad()
def evaluate_loss(net, X, groups, Y, *, device, batch_size: int = 8192) -> float:
    net.eval()
    tot = 0.0
    for s in range(0, X.shape[0], batch_size):
        xb = torch.tensor(X[s : s + batch_size], dtype=torch.float32, device=device)
        gb = torch.tensor(groups[s : s + batch_size], dtype=torch.int64, device=device)
        yb = torch.tensor(Y[s : s + batch_size], dtype=torch.float32, device=device)
        tot += float(((net(xb, gb) - yb) ** 2).mean()) * xb.shape[0]
    return tot / max(1, X.shape[0])


__all__ = ["ContentDAE", "ShrinkageCNN", "evaluate_loss", "fit", "setup"]
