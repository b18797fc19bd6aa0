"""Noise on mesh animations (T, n, 3) with shared faces (Sections 3.4, 4.10)."""

from __future__ import annotations

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_frames, as_rng, check_choice, deprecated_flag
from ..geometry.primitives import vertex_normals
from . import static
from ._core import NoiseResult, check_fraction, check_level, mean_spacing


def spatial_mask(
    frames,
    F,
    *,
    fraction: float = 0.2,
    level: float = 0.3,
    rng=None,
    region: str = "random",
    distribution: str = "gaussian",
    direction: str = "normal",
) -> NoiseResult:
    """Noise on the same ``round(fraction * n)`` vertices, with the same pattern, in every frame.

    The mask is random (``region="random"``) or a patch around a random seed (``"patch"``); each
    masked vertex moves by one draw of ``distribution`` (deviation ``level * l``) times its normal in
    each frame, or by one fixed vector (``direction="random"``).
    """
    A = as_frames(frames)
    T, n, _ = A.shape
    F = as_faces(F, n, "F")
    fraction = check_fraction(fraction)
    level = check_level(level)
    check_choice(region, "region", ("random", "patch"))
    check_choice(distribution, "distribution", ("gaussian", "uniform"))
    check_choice(direction, "direction", ("normal", "random"))
    rng = as_rng(rng)
    k = int(round(fraction * n))
    if region == "random":
        idx = rng.choice(n, size=k, replace=False)
    else:
        seed = int(rng.integers(n))
        d = np.linalg.norm(A[0] - A[0, seed], axis=1)
        idx = np.argsort(d, kind="stable")[:k]
    mask = np.zeros(n, dtype=bool)
    mask[idx] = True
    sigma0 = level * float(np.mean([mean_spacing(A[t], F) for t in range(T)]))
    along = direction == "normal"
    c = static._draw(distribution, rng, k, along, np.full(k, sigma0))
    D = np.zeros_like(A)
    for t in range(T):
        if along:
            D[t, idx] = c[:, None] * vertex_normals(A[t], F)[idx]
        else:
            D[t, idx] = c
    return NoiseResult(A + D, D, mask, np.where(mask, sigma0, 0.0), None, "spatial-mask")


ANIMATION_KINDS = (
    "gaussian",
    "uniform",
    "impulsive",
    "spatial-mask",
    "spatial_mask",
    "quantization",
    "quantisation",
)


def animation_noise(
    frames,
    F,
    *,
    kind: str = "gaussian",
    level: float = 0.3,
    rng=None,
    fraction: float | None = None,
    direction: str = "normal",
    return_result: bool | None = None,
):
    """Noise on every frame of an animation; returns the noisy frames (T, n, 3).

    ``"gaussian"``, ``"uniform"``, ``"quantization"`` per frame; ``"impulsive"`` a new subset per
    frame; ``"spatial-mask"`` as :func:`spatial_mask`. :func:`animation_noise_result` returns the
    :class:`NoiseResult` (``return_result`` is deprecated).
    """
    if return_result is not None:
        deprecated_flag(
            "animation_noise", "return_result", "animation_noise_result() (the NoiseResult)"
        )
    res = animation_noise_result(
        frames, F, kind=kind, level=level, rng=rng, fraction=fraction, direction=direction
    )
    return res if return_result else res.vertices


def animation_noise_result(
    frames,
    F,
    *,
    kind: str = "gaussian",
    level: float = 0.3,
    rng=None,
    fraction: float | None = None,
    direction: str = "normal",
) -> NoiseResult:
    """:func:`animation_noise` returning the :class:`NoiseResult` (frames and ground truth)."""
    check_choice(kind, "kind", ANIMATION_KINDS)
    if fraction is not None and kind not in ("impulsive", "spatial-mask", "spatial_mask"):
        raise InvalidInputError(
            f"`fraction` applies to kinds 'impulsive' and 'spatial-mask' only; got kind={kind!r}."
        )
    A = as_frames(frames)
    F = as_faces(F, A.shape[1], "F")
    if kind in ("spatial-mask", "spatial_mask"):
        return spatial_mask(
            A,
            F,
            fraction=0.2 if fraction is None else fraction,
            level=level,
            rng=rng,
            direction=direction,
        )
    check_level(level)
    rng = as_rng(rng)
    per = [
        static.apply_result(
            A[t], F, kind=kind, level=level, rng=rng, fraction=fraction, direction=direction
        )
        for t in range(A.shape[0])
    ]
    return NoiseResult(
        np.stack([p.vertices for p in per]),
        np.stack([p.displacement for p in per]),
        np.stack([p.mask for p in per]),
        np.stack([p.scale for p in per]),
        None,
        per[0].kind,
    )
