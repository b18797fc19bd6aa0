"""The learned denoisers as plugins of :mod:`spectrageo.denoise`: the ``spectrageo.denoisers`` entry
point calls :func:`register` on a missing name, so users need not import :mod:`spectrageo.learn`.
"""

from __future__ import annotations

from .bm3d_cnn import bm3d_cnn
from .dae import dae, dae_animation


def _bm3d_cnn(V, F, *, weights=None, n_iter=None, vertex_iter=None):
    return bm3d_cnn(V, F, weights=weights, n_iter=n_iter, vertex_iter=vertex_iter)


def _dae(V, F, *, weights=None, n_iter=None, vertex_iter=None):
    return dae(V, F, weights=weights, n_iter=n_iter, vertex_iter=vertex_iter)


def register() -> None:
    """Register ``bm3d-cnn`` and ``dae`` (static meshes) and ``dae`` (animations); idempotent."""
    from .. import denoise

    denoise.register(
        "bm3d-cnn",
        summary="block-matching 3D CNN on images of guided normals (learned; numpy inference)",
        reference="Thesis Section 5.1.4, Algorithm 5, Eq. (5.38)-(5.41)",
    )(_bm3d_cnn)
    denoise.register(
        "dae",
        summary="feature-aware content-wise denoising autoencoders (learned; numpy inference)",
        reference="Thesis Section 5.1.3, Algorithm 4",
    )(_dae)
    denoise.register_animation_method("dae", dae_animation)
