"""Data-driven mesh denoising (thesis Sections 5.1.3 and 5.1.4).

:func:`bm3d_cnn` (block-matching 3D CNN, Algorithm 5) and :func:`dae` / :func:`dae_animation`
(content-wise denoising autoencoders, Algorithm 4) run in numpy from ``.npz`` weights
(:func:`load_weights`); :mod:`spectrageo.learn.train` trains them (needs PyTorch). Both are
registered as denoisers (``spectrageo denoise --method bm3d-cnn|dae``).
"""

from ._options import BM3DCNNTrainOptions, DAETrainOptions, FramesTrainOptions, TrainOptions
from ._weights import DEFAULT_WEIGHTS, default_weights, load_weights, save_weights
from .bm3d_cnn import BM3DCNNModel, bm3d_cnn
from .dae import DAEModel, dae, dae_animation, train_frames_model


def evaluate_learned(*args, **kwargs):
    """See :func:`spectrageo.learn.evaluate.evaluate_learned`."""
    from .evaluate import evaluate_learned as _ev

    return _ev(*args, **kwargs)


__all__ = [
    "BM3DCNNModel",
    "BM3DCNNTrainOptions",
    "DAEModel",
    "DAETrainOptions",
    "DEFAULT_WEIGHTS",
    "FramesTrainOptions",
    "TrainOptions",
    "bm3d_cnn",
    "dae",
    "dae_animation",
    "default_weights",
    "evaluate_learned",
    "load_weights",
    "save_weights",
    "train_frames_model",
]
