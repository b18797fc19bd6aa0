"""Data-driven mesh denoising (thesis Sections 5.1.3 and 5.1.4).

* :func:`bm3d_cnn` -- image-based denoising with a block-matching 3D CNN (Algorithm 5);
* :func:`dae` / :func:`dae_animation` -- feature-aware content-wise denoising autoencoders
  (Algorithm 4), for static meshes (shipped weights) and animations (trained at denoise time on
  the first frames, in numpy);
* :mod:`spectrageo.learn.train` -- training of the shipped weights (needs PyTorch, the ``learn``
  extra); :func:`evaluate_learned` -- the learned methods against TSGSP and BNF.

Inference needs no PyTorch, only the base install (numpy, scipy and, for the bm3d-cnn's fast
path and its images, numba kernels): the weights are ``.npz`` files with their metadata
(:func:`load_weights`); the shipped ones live in ``spectrageo/learn/weights/``. Both methods are
registered as denoisers (``spectrageo denoise --method bm3d-cnn|dae``).
"""

from ._weights import DEFAULT_WEIGHTS, default_weights, load_weights, save_weights
from .bm3d_cnn import BM3DCNNModel, bm3d_cnn
from .dae import DAEModel, dae, dae_animation, train_frames_model


def evaluate_learned(*args, **kwargs):
    """See :func:`spectrageo.learn.evaluate.evaluate_learned`."""
    from .evaluate import evaluate_learned as _ev

    return _ev(*args, **kwargs)


__all__ = [
    "BM3DCNNModel",
    "DAEModel",
    "DEFAULT_WEIGHTS",
    "bm3d_cnn",
    "dae",
    "dae_animation",
    "default_weights",
    "evaluate_learned",
    "load_weights",
    "save_weights",
    "train_frames_model",
]
