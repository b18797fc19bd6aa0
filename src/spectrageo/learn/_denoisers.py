"""Registers the learned denoisers ``bm3d-cnn`` and ``dae`` in :mod:`spectrageo.denoise` (numpy
inference of the shipped or given weights; torch is not needed)."""

from __future__ import annotations

from ..denoise._registry import register
from .bm3d_cnn import bm3d_cnn
from .dae import dae


@register(
    "bm3d-cnn",
    summary="block-matching 3D CNN on images of guided normals (learned; numpy inference)",
    reference="Thesis Section 5.1.4, Algorithm 5, Eq. (5.38)-(5.41)",
)
def _bm3d_cnn(V, F, *, weights=None, n_iter=None, vertex_iter=None):
    return bm3d_cnn(V, F, weights=weights, n_iter=n_iter, vertex_iter=vertex_iter)


@register(
    "dae",
    summary="feature-aware content-wise denoising autoencoders (learned; numpy inference)",
    reference="Thesis Section 5.1.3, Algorithm 4",
)
def _dae(V, F, *, weights=None, n_iter=None, vertex_iter=None):
    return dae(V, F, weights=weights, n_iter=n_iter, vertex_iter=vertex_iter)
