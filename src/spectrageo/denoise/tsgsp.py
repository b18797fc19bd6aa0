"""Two-stage graph spectral processing (TSGSP) for feature-preserving mesh denoising (thesis
Section 5.1.1, Algorithms 1-2, Appendix B): the MBL coarse step (:func:`coarse`) and the
feature-aware fine step (:func:`fine`), joined by :func:`tsgsp`."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_points, check_choice, check_positive
from ..geometry import vertex_normals
from . import _tsgsp_coarse, _tsgsp_fine
from ._guard import FOLD_STOP, apply_trust, is_folded, noise_sigma, unfold
from ._options import take_fields
from ._table import register
from ._tsgsp_coarse import CoarseOptions, CoarseResult, coarse, estimate_noise, scale_weights
from ._tsgsp_fine import BIMODALITY, CURVED_FINISH, PRESETS, WIDE_SPREAD, FineOptions, fine
from ._tsgsp_kernels import select_neighborhoods

__all__ = [
    "BIMODALITY",
    "CURVED_FINISH",
    "PRESETS",
    "WIDE_SPREAD",
    "CoarseOptions",
    "CoarseResult",
    "FineOptions",
    "GateMeasures",
    "coarse",
    "estimate_noise",
    "fine",
    "scale_weights",
    "select_neighborhoods",
    "tangent_weight",
    "tsgsp",
]


def _is_bool(x) -> bool:
    return isinstance(x, bool | np.bool_)


@dataclass(frozen=True)
class GateMeasures:
    """What :func:`spectrageo.denoise.denoise`'s gate measured: the noise deviation ``sigma``
    (Eq. N1) and the folded decision (Eq. N10); None: measured by :func:`tsgsp`."""

    sigma: float | None = None
    folded: bool | None = None

    def __post_init__(self):
        if self.sigma is not None:
            check_positive(self.sigma, "sigma", allow_zero=True)
        if self.folded is not None and not _is_bool(self.folded):
            raise InvalidInputError(f"`folded` must be None, True or False; got {self.folded!r}.")


def tangent_weight(R, Rn) -> float:
    """Weight ``beta`` of the tangential residual in TSGSP's first-round blend (Eqs. T1-T2).

    With ``R = V - V_c``, ``R_n`` its part along the coarse normals and
    ``rho^2 = mean |R - R_n|^2 / mean |R_n|^2``::

        (T1)  beta = clip((sqrt 2 - rho) / (sqrt 2 - 1), 0, 1)     for rho^2 <= 2
        (T2)  beta = 1 - 2 / rho^2                                 for rho^2 > 2

    Not in the thesis; see docs/decisions.md#tsgsp-tangent-weight."""
    en = float(np.mean(Rn * Rn))
    if not en > 0:
        return 1.0
    rho2 = float(np.mean((R - Rn) ** 2) / en)
    if rho2 > 2.0:  # (T2) more than isotropic noise can explain: Wiener gain of the rest
        return 1.0 - 2.0 / rho2
    rho = float(np.sqrt(rho2))
    return float(np.clip((np.sqrt(2.0) - rho) / (np.sqrt(2.0) - 1.0), 0.0, 1.0))


def _tsgsp_legacy(legacy: dict, coarse_opts, fine_opts, measured):
    if "source" in legacy:
        raise InvalidInputError("`source` is set by `input_weight`; do not pass it to tsgsp.")
    if "pre" in legacy:
        pre = legacy.pop("pre")
        if pre not in (None, "coarse"):
            raise InvalidInputError(f"`pre` must be None or 'coarse'; got {pre!r}.")
        warnings.warn("tsgsp(..., pre=...) is deprecated and has no effect (the coarse step "
                      "is always part of TSGSP).", DeprecationWarning, stacklevel=3)  # fmt: skip
    if "coarse_options" in legacy:
        copts = dict(legacy.pop("coarse_options") or {})
        copts.pop("full_output", None)
        if copts:
            coarse_opts = take_fields(CoarseOptions, coarse_opts, copts, "tsgsp", "coarse")
            if copts:
                raise TypeError(
                    f"coarse() got an unexpected keyword argument {next(iter(copts))!r}"
                )
    gate = {k: legacy.pop(k) for k in ("sigma_z", "folded") if k in legacy}
    if gate:
        warnings.warn(
            f"tsgsp(..., {', '.join(f'{k}=' for k in gate)}) is deprecated; pass "
            "measured=GateMeasures(sigma=..., folded=...) instead.",
            DeprecationWarning,
            stacklevel=3,
        )
        measured = GateMeasures(sigma=gate.get("sigma_z"), folded=gate.get("folded"))
    fine_opts = take_fields(FineOptions, fine_opts, legacy, "tsgsp", "fine")
    if legacy:
        raise TypeError(f"tsgsp() got an unexpected keyword argument {next(iter(legacy))!r}")
    return coarse_opts, fine_opts, measured


@register(
    "tsgsp",
    summary="two-stage graph spectral processing: MBL coarse step + feature-aware fine step",
    reference="thesis Section 5.1.1, Algorithms 1-2 (Arvanitis et al., IEEE TVCG 2019)",
    presets=tuple(PRESETS),
)
def tsgsp(
    V,
    F,
    *,
    preset: str = "default",
    coarse: CoarseOptions | None = None,
    fine: FineOptions | None = None,
    input_weight: float = 0.7,
    input_tangent: float | str = "auto",
    trust: float | None = 6.0,
    folds: bool = True,
    unfold_fine: bool = True,
    measured: GateMeasures | None = None,
    rng=0,
    **legacy,
) -> np.ndarray:
    """Two-stage graph spectral processing (Algorithm 2): :func:`coarse`, then :func:`fine`.

    The first fine round filters the normals of ``V_c + input_weight (R_n + beta R_t)`` (``V_c``
    the coarse mesh, ``R = V - V_c`` split along the coarse normals, ``beta`` of
    :func:`tangent_weight`) with features, patches and weights from ``V_c`` (reading choice (e)).
    Not in the thesis: the trust bound (docs/decisions.md#denoise-trust-region) and the folded-mesh
    rule (Eq. N10; docs/decisions.md#denoise-fold-rule, #tsgsp-unfold-fine). Meshes under 8
    vertices get the fine step only.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    preset : {"default", "scan", "cad"}
        Fine-step preset (:data:`PRESETS`, Fig. 5.16).
    coarse, fine : CoarseOptions, FineOptions, optional
        Options of the two steps.
    input_weight : float in [0, 1]
        Weight of the noisy mesh in the blend (0: Algorithm 2 as written); chosen on the tuning
        split, see docs/decisions.md#tsgsp-fine-weights.
    input_tangent : float in [0, 1] or "auto"
        ``beta``; "auto": Eqs. (T1)-(T2).
    trust : float or None
        Largest displacement in noise deviations; chosen on the tuning split, see
        docs/decisions.md#denoise-trust-region.
    folds, unfold_fine : bool
        Apply the folded-mesh rule; run the fine step once the folds are gone.
    measured : GateMeasures, optional
    rng : seed or Generator
    **legacy
        Old keywords (``coarse_options``, fine-step fields, ``sigma_z``, ``folded``, ``pre``):
        deprecated.

    Returns
    -------
    (n, 3) float64
    """
    check_choice(preset, "preset", tuple(PRESETS))
    if (
        isinstance(input_weight, (bool, np.bool_))
        or not isinstance(input_weight, (int, float, np.integer, np.floating))
        or not 0 <= input_weight <= 1
    ):
        raise InvalidInputError(f"`input_weight` must be in [0, 1]; got {input_weight!r}.")
    coarse, fine, measured = _tsgsp_legacy(legacy, coarse, fine, measured)
    if not (
        (isinstance(input_tangent, str) and input_tangent == "auto")
        or (
            isinstance(input_tangent, (int, float, np.integer, np.floating))
            and not isinstance(input_tangent, (bool, np.bool_))
            and 0 <= input_tangent <= 1
        )
    ):
        raise InvalidInputError(
            f"`input_tangent` must be 'auto' or in [0, 1]; got {input_tangent!r}."
        )
    if trust is not None:
        check_positive(trust, "trust")
    V = as_points(V, "V")
    if not _is_bool(folds):
        raise InvalidInputError(f"`folds` must be True or False; got {folds!r}.")
    if not _is_bool(unfold_fine):
        raise InvalidInputError(f"`unfold_fine` must be True or False; got {unfold_fine!r}.")
    if measured is None:
        measured = GateMeasures()
    elif not isinstance(measured, GateMeasures):
        raise InvalidInputError(f"`measured` must be a GateMeasures; got {measured!r}.")
    folded = measured.folded
    if folds and (is_folded(V, F) if folded is None else folded):
        X, share = unfold(V, F, return_share=True)
        if unfold_fine and share < FOLD_STOP:
            X = _tsgsp_fine.fine(X, F, preset=preset, options=fine)
        return X
    if V.shape[0] < 8 and coarse is None:
        return _tsgsp_fine.fine(V, F, preset=preset, options=fine)  # too few for a spectrum
    cr = _tsgsp_coarse.coarse(V, F, options=coarse, rng=rng)
    Vc = cr.vertices
    if trust is not None:
        if coarse is not None and coarse.noise_var is not None:
            sigma = float(np.sqrt(cr.noise_var))
        elif measured.sigma is not None:
            sigma = float(measured.sigma)
        else:
            sigma = noise_sigma(V, F=F)[0]
        if not (cr.noise_var > 0 and sigma > 0):
            return V.copy()  # no noise found: nothing to remove
    source = None
    if input_weight > 0:
        R = V - Vc
        Nc = vertex_normals(Vc, F)
        Rn = np.sum(R * Nc, axis=1, keepdims=True) * Nc
        beta = tangent_weight(R, Rn) if input_tangent == "auto" else float(input_tangent)
        if beta < 1:
            source = Vc + float(input_weight) * (Rn + beta * (R - Rn))
        else:  # the plain blend, written so that results stay bit-identical
            source = Vc + float(input_weight) * R
    out = _tsgsp_fine.fine(Vc, F, preset=preset, options=fine, source=source)
    if trust is None:
        return out
    return apply_trust(V, out, float(trust) * sigma)
