"""TSGSP with saliency-aware patches (the denoiser ``tsgsp-saliency``, registered through the
``spectrageo.denoisers`` entry point)."""

from __future__ import annotations

import warnings

import numpy as np

from .._errors import InvalidInputError
from ..denoise import register as _register_denoiser
from ..denoise import tsgsp as _tsgsp
from ..denoise.tsgsp import CoarseOptions
from .denoise import saliency_denoise

__all__ = ["register", "tsgsp_saliency"]


def tsgsp_saliency(
    V, F, *, coarse: CoarseOptions | None = None, rng=0, **saliency_options
) -> np.ndarray:
    """TSGSP's coarse step (Algorithm 1, options ``coarse``, seed ``rng``), then saliency-aware
    guided normal filtering (:func:`~spectrageo.saliency.saliency_denoise`, Eqs. 6.20-6.23,
    ``saliency_options``) of the coarse mesh; ``pre`` and a ``coarse_options`` dict are deprecated."""
    pre = saliency_options.pop("pre", None)
    if pre not in (None, "coarse"):
        raise InvalidInputError(f"`pre` must be None or 'coarse'; got {pre!r}.")
    if "coarse_options" in saliency_options:
        given = dict(saliency_options.pop("coarse_options") or {})
        given.pop("full_output", None)
        warnings.warn(
            "tsgsp_saliency(..., coarse_options=...) is deprecated; pass "
            "coarse=CoarseOptions(...) instead.",
            DeprecationWarning,
            stacklevel=2,
        )
        coarse = CoarseOptions(**given) if coarse is None else coarse
    Vc = _tsgsp.coarse(V, F, options=coarse, rng=rng).vertices
    return saliency_denoise(Vc, F, **saliency_options)


def register() -> None:
    """Register ``tsgsp-saliency`` in :mod:`spectrageo.denoise`."""
    _register_denoiser(
        "tsgsp-saliency",
        summary="TSGSP coarse step + saliency-aware guided normal filtering (Eq. 6.20-6.23)",
        reference="thesis Section 5.1.1 (coarse step) and Section 6 Eq. 6.20-6.23 "
        "(saliency-aware patches)",
        trusted=True,
    )(tsgsp_saliency)
