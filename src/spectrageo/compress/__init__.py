"""Compression of static triangle meshes into ``.sgc`` files (thesis Sections 5.2.1 and 5.2.3).

* :func:`encode` ``(V, F) -> bytes`` and :func:`decode` ``bytes -> (V, F)``; :func:`info` reads
  the header (method, counts, bits per vertex, parameters) without decoding the geometry.
* Methods: ``"spectral"`` (block spectral coding on overlapped submeshes with dictionaries that the
  decoder recomputes from the connectivity by orthogonal iterations, Algorithms 6-8, Eq. 5.42-5.45;
  progressive), ``"feature"`` (feature-aware high-pass quantisation, Algorithm 9, Eq. 5.53-5.54)
  and ``"saliency"`` (saliency classes choose the delta coordinates that are sent, Algorithm 10).
* Rate control: ``bpv=`` (whole file, connectivity included) or ``error=`` (RMS vertex error as
  a fraction of the bounding-box diagonal); the quantisation step is found by bisection so that
  the request is met within 5 %. ``feature`` and ``saliency`` also choose their level of detail
  (the share of the vertices whose delta coordinates are sent, Algorithm 9 step 5, Algorithm 10
  steps 4-5) unless ``feature_fraction`` / ``class_keep``, ``ratio`` or ``mask`` is given: the
  level with the smallest RMS error for ``bpv=``, the smallest file for ``error=`` (see
  :mod:`spectrageo.compress._feature`).
* The vertex order and the faces (order and corner order) are kept exactly unless
  ``reorder=True``, which lets the codec renumber vertices and faces for a smaller connectivity
  stream (:func:`info` then reports ``"reordered": true``).

The container (magic, version, header, checksummed chunks) is described in
:mod:`spectrageo.compress._container`; damaged, truncated or foreign data raise
:class:`~spectrageo.InvalidInputError`.

Determinism: the decoder recomputes the spectral dictionaries with the same code as the encoder
(seeded METIS, seeded orthogonal iterations), so a file decodes to the same mesh with the same
spectrageo version and numerical libraries; across platforms the result can differ at the level
of floating-point rounding of the dictionaries.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_choice
from . import _animation, _connectivity, _container

__all__ = [
    "ANIMATION_METHODS",
    "METHODS",
    "StreamDecoder",
    "StreamEncoder",
    "decode",
    "decode_animation",
    "encode",
    "encode_animation",
    "info",
    "info_animation",
]

METHODS = ("spectral", "feature", "saliency")
TAG_CONNECTIVITY = 1
#: relative tolerance of the rate control (the issue's contract is 5 %)
RATE_TOLERANCE = 0.05
_AIM = 0.03  # the bisection stops within 3 % to stay inside 5 % after rounding
_STEP_MIN, _STEP_MAX = 1e-7, 4.0

#: default quantisation step (fraction of the bounding-box diagonal) when no rate is requested
DEFAULT_STEP = {"spectral": 1e-3, "feature": 4e-4, "saliency": 4e-4}


def _module(method: str):
    if method == "spectral":
        from . import _spectral as m
    else:
        from . import _feature as m
    return m


def _check_rate(bpv, error) -> None:
    if bpv is not None and error is not None:
        raise InvalidInputError("give at most one of `bpv` and `error`.")
    for name, v in (("bpv", bpv), ("error", error)):
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, int | float | np.integer | np.floating):
            raise InvalidInputError(f"`{name}` must be a positive number; got {v!r}.")
        if not (math.isfinite(float(v)) and float(v) > 0):
            raise InvalidInputError(f"`{name}` must be a positive number; got {v!r}.")


def encode(
    V,
    F,
    *,
    method: str = "spectral",
    bpv: float | None = None,
    error: float | None = None,
    reorder: bool = False,
    step: float | None = None,
    **options: Any,
) -> bytes:
    """Compress a triangle mesh into ``.sgc`` bytes.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
        Every vertex index in ``0..n-1``; vertices that no face uses are coded too.
    method : {"spectral", "feature", "saliency"}
    bpv : float, optional
        Target size in bits per vertex of the whole file (header and connectivity included).
    error : float, optional
        Target RMS vertex error ``sqrt(mean ||v - v'||^2)`` as a fraction of the bounding-box
        diagonal. With either, ``feature`` (without ``feature_fraction``, ``ratio``, ``mask``)
        and ``saliency`` (without ``class_keep``, ``ratio``, ``mask``) try the levels of
        :data:`spectrageo.compress._feature.LEVELS` and keep the best.
    reorder : bool
        Let the codec renumber vertices and faces (smaller connectivity); the decoded mesh is then
        the same surface with another vertex and face order.
    step : float, optional
        Quantisation step as a fraction of the diagonal, used when neither ``bpv`` nor ``error``
        is given (default :data:`DEFAULT_STEP`).
    **options
        Method parameters. ``spectral``: ``submesh_size`` (300), ``overlap`` (0.1), ``k``
        (dictionary size per submesh, default ``submesh_size``: the quantiser, not a cut-off,
        drops the high frequencies), ``basis`` ("oi", "exact", "doi"), ``zeta`` (4),
        ``n_iter`` (1), ``eps`` (DOI residual threshold), ``seed`` (0). ``feature`` /
        ``saliency``: see :mod:`spectrageo.compress._feature`.

    Returns
    -------
    bytes
        The ``.sgc`` file content.
    """
    check_choice(method, "method", METHODS)
    _check_rate(bpv, error)
    if step is not None and (bpv is not None or error is not None):
        raise InvalidInputError("`step` cannot be combined with `bpv` or `error`.")
    if step is not None and not (isinstance(step, int | float) and _STEP_MIN <= step <= _STEP_MAX):
        raise InvalidInputError(f"`step` must be in [{_STEP_MIN}, {_STEP_MAX}]; got {step!r}.")
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    if V.shape[0] > _container.MAX_COUNT or F.shape[0] > _container.MAX_COUNT:
        raise InvalidInputError("the mesh is too large for the .sgc format (2**28 elements).")
    if not isinstance(reorder, bool | np.bool_):
        raise InvalidInputError(f"`reorder` must be True or False; got {reorder!r}.")
    if reorder:
        V, F, _perm = _connectivity.reorder(V, F)
    lo, hi = V.min(axis=0), V.max(axis=0)
    origin = 0.5 * (lo + hi)
    diag = float(np.linalg.norm(hi - lo))
    scale = diag if diag > 0 else 1.0
    X = (V - origin) / scale
    conn = _connectivity.encode_faces(F)
    mod = _module(method)
    plan = mod.make_plan(X, F, method, options)

    def build(s: float, p=plan) -> bytes:
        c = _container.Container(
            method,
            V.shape[0],
            F.shape[0],
            tuple(float(x) for x in origin),
            float(scale),
            p.params(s),
            bool(reorder),
            [(TAG_CONNECTIVITY, conn), *p.chunks(s)],
        )
        return c.to_bytes()

    n = V.shape[0]
    if bpv is None and error is None:
        return build(DEFAULT_STEP[method] if step is None else float(step))
    # the delta codecs choose their level of detail (Algorithm 9 step 5, Algorithm 10 steps
    # 4-5) unless it is given
    given = {"feature": "feature_fraction", "saliency": "class_keep"}.get(method)
    chosen = given is not None and not {given, "ratio", "mask"} & set(options)
    plans = plan.levels() if chosen else [plan]

    def rms(p, s) -> float:  # s=None: unquantised (the floor of the method)
        d = p.reconstruct(s) - X
        return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))

    best, failure = None, None
    for p in plans:
        try:
            if bpv is not None:
                s, data = _bisect(
                    lambda s, p=p: (8.0 * len(build(s, p)) / n, None),
                    float(bpv),
                    increasing=False,
                    what="bpv",
                )
                key = rms(p, s) if len(plans) > 1 else 0.0
            else:
                s = _error_step(lambda s, p=p: rms(p, s), float(error), method)
                key = len(build(s, p)) if len(plans) > 1 else 0
        except InvalidInputError as exc:
            failure = exc  # the last level (uniform) reaches the widest range of requests
            continue
        if best is None or key < best[0]:
            best = (key, p, s)
    if best is None:
        raise failure
    return build(best[2], best[1])


def _error_step(measure, target: float, method: str) -> float:
    """The quantisation step whose RMS error (``measure(step)``) is within 3 % of ``target``."""
    floor = measure(None)
    if floor > (1 - _AIM) * target:
        raise InvalidInputError(
            f"`error` = {target:g} is below what method {method!r} reaches with these options "
            f"(about {floor:.3g} at the finest step); "
            + (
                "raise `k` or `submesh_size`."
                if method == "spectral"
                else "send more deltas (`feature_fraction`, `class_keep`) or give `ratio` >= 1."
            )
        )
    s, _ = _bisect(lambda s: (measure(s), None), target, increasing=True, what="error")
    return s


def _bisect(measure, target: float, *, increasing: bool, what: str):
    """Log-bisection on the quantisation step until ``measure(step)`` is within 3 % of target.

    ``increasing``: the measure grows with the step (error) or falls with it (bpv).
    """
    lo, hi = math.log(_STEP_MIN), math.log(_STEP_MAX)
    f_lo, d_lo = measure(math.exp(lo))
    f_hi, d_hi = measure(math.exp(hi))
    best = None
    for f, s, d in ((f_lo, lo, d_lo), (f_hi, hi, d_hi)):
        if abs(f - target) <= _AIM * target:
            return math.exp(s), d
    small, large = (f_lo, f_hi) if increasing else (f_hi, f_lo)
    if target < small * (1 - RATE_TOLERANCE):
        raise InvalidInputError(
            f"`{what}` = {target:g} cannot be reached: the smallest value this method gives here "
            f"is {small:.4g}" + (" (the connectivity and header alone)." if what == "bpv" else ".")
        )
    if target > large * (1 + RATE_TOLERANCE):
        raise InvalidInputError(
            f"`{what}` = {target:g} cannot be reached: the largest value this method gives here "
            f"is {large:.4g}."
        )
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        f, d = measure(math.exp(mid))
        err = abs(f - target) / target
        if best is None or err < best[0]:
            best = (err, mid, d)
        if err <= _AIM:
            break
        if (f < target) == increasing:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-6:
            break
    err, s, d = best
    if err > RATE_TOLERANCE:
        raise InvalidInputError(
            f"`{what}` = {target:g} could not be met within 5 % (closest: {err:.1%} away); the "
            "rate of this mesh jumps at that point."
        )
    return math.exp(s), d


def _parse(data, partial: bool):
    if _animation.is_animation(data):
        raise InvalidInputError(
            "this is a compressed animation (.sga); use spectrageo.compress.decode_animation."
        )
    c = _container.parse(data, partial=partial)
    if not c.chunks or c.chunks[0][0] != TAG_CONNECTIVITY:
        raise InvalidInputError(".sgc data lacks its connectivity chunk.")
    return c


def decode(data, *, partial: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Decompress ``.sgc`` bytes into ``(V, F)``: (n, 3) float64 and (m, 3) int64.

    ``partial=True`` accepts a prefix of a file (a progressive stream cut short): the geometry
    layers that are complete are used and the missing ones taken as zero, which for the spectral
    method gives a smoother, coarser mesh. Without it a truncated file is an error.

    Raises
    ------
    InvalidInputError
        Not an ``.sgc`` file, unsupported version, checksum mismatch, truncated, or malformed.
    """
    c = _parse(data, partial)
    n, m = c.n_vertices, c.n_faces
    F = _connectivity.decode_faces(c.chunks[0][1], n, m)
    mod = _module(c.method)
    X = mod.decode(c.params, c.chunks[1:], F, n, c.method)
    if not np.isfinite(X).all():
        raise InvalidInputError(".sgc data decodes to non-finite coordinates (corrupted).")
    V = X * c.scale + np.asarray(c.origin)
    return V, F


def info(data) -> dict:
    """Header summary of ``.sgc`` bytes: method, version, counts, size, bpv, parameters.

    For ``feature`` and ``saliency`` files ``parameters`` also holds ``sent_share``, the share of
    the vertices whose delta coordinates are sent at the fine step (the level of detail).
    """
    c = _parse(data, False)
    mod = _module(c.method)
    size = len(data)
    conn = len(c.chunks[0][1])
    params = mod.describe(c.params, c.method)
    if c.method != "spectral":
        params["sent_share"] = round(mod.sent_share(c.chunks[1:], c.n_vertices), 6)
    return {
        "format": "sgc",
        "version": _container.FORMAT_VERSION,
        "method": c.method,
        "n_vertices": c.n_vertices,
        "n_faces": c.n_faces,
        "bytes": size,
        "bpv": 8.0 * size / c.n_vertices,
        "connectivity_bpv": 8.0 * conn / c.n_vertices,
        "geometry_bpv": 8.0 * (size - conn) / c.n_vertices,
        "reordered": c.reordered,
        "order_preserved": not c.reordered,
        "n_layers": len(c.chunks) - 1,
        "parameters": params,
    }


# ----------------------------------------------------------------------------- animations (.sga)
#: animation methods (thesis Section 5.2.2); see :mod:`spectrageo.compress._animation`
ANIMATION_METHODS = _animation.ALL_METHODS


def encode_animation(
    frames,
    F,
    *,
    method: str = "blocks",
    bpvf: float | None = None,
    error: float | None = None,
    step: float | None = None,
    **options: Any,
) -> bytes:
    """Compress a mesh animation with fixed connectivity into ``.sga`` bytes (Section 5.2.2).

    Delta coordinates projected on eigen-trajectories (Eq. 5.46-5.52; see
    :mod:`spectrageo.compress._animation` for the methods and the file layout), the scalable
    layered streaming codec of Section 5.2.4 (``method="layered"``, Algorithm 11; see
    :mod:`spectrageo.compress._layered`), or ``"pca-spectral"``: eigen-trajectories of the
    whole sequence with the partitioned GFT of Section 5.2.1 as the spatial transform (a
    combination of the two sections, not a method of the thesis; see
    :mod:`spectrageo.compress._pca_spectral`).

    Parameters
    ----------
    frames : (T, n, 3) float or MeshAnimation
    F : (m, 3) int
        Shared faces; vertex order and faces are kept exactly.
    method : {"pca", "pca-q", "pca-qs", "pca-qp", "blocks", "pca-spectral", "layered"}
    bpvf : float, optional
        Target size of the whole file in bits per vertex per frame (met within 5 %).
    error : float, optional
        Target KG error (Karni & Gotsman, in percent, :func:`spectrageo.metrics.kg_error`), met
        within 5 %.
    step : float, optional
        Quantisation step of the delta-coordinate projections (fraction of the bounding-box
        diagonal; default 2e-4) when no target is given; for ``pca`` the number of kept
        coefficients per coordinate.
    **options
        ``block`` (frames per block of ``blocks``, 16), ``anchors`` (fraction of anchor vertices
        of pca-qs / pca-qp / blocks, 0.01), ``anchor_ratio`` (anchor step / step, 0.5),
        ``weight`` (anchor weight in Eq. 5.51, 1), ``basis`` ("oi" orthogonal iterations started
        from the previous block, or "exact"), ``n_iter`` (2), ``rd`` (row-dropping strength, 1).
        ``pca-spectral`` uses none of them (they are accepted, as ``pca`` accepts ``block``);
        its ``step`` is that of the GFT coefficients. ``layered`` takes ``layer`` (fraction of the vertices sent per frame, 0.1; ``bpvf``
        chooses it per frame instead), ``refresh`` (a refresh frame every that many frames,
        16; 0 = never) and ``fine`` (the RPCA/ISVD fine reconstruction, off); its ``step``
        (default 1e-3) is a fraction of twice the first frame's diagonal; ``error`` bisects the
        layer, or, below what every vertex sent at the default step gives, the step with every
        vertex sent.

    Returns
    -------
    bytes
        The ``.sga`` file content (stream header, one segment per block, frame index).
    """
    return _animation.encode_animation(
        frames, F, method=method, bpvf=bpvf, error=error, step=step, **options
    )


def decode_animation(data, *, partial: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Decompress ``.sga`` bytes into ``(frames, F)``: (T, n, 3) float64 and (m, 3) int64.

    ``partial=True`` accepts a truncated file and returns the frames of every complete block
    (compare ``frames.shape[0]`` with :func:`info_animation` of the full file, or use
    :class:`StreamDecoder`, to know what is missing). Damaged data raise
    :class:`~spectrageo.InvalidInputError`.
    """
    return _animation.decode_animation(data, partial=partial)


def info_animation(data) -> dict:
    """Header summary of ``.sga`` bytes: method, frames, counts, bpvf, blocks, parameters."""
    return _animation.info_animation(data)


class StreamEncoder(_animation.StreamEncoder):
    """Streaming encoder (``blocks`` or ``layered``): :meth:`push` one frame at a time,
    :meth:`close` at the end.

    ``method="layered"`` (Section 5.2.4) emits one segment per frame -- the header and the whole
    first frame with the first push, so the first frame decodes from the first packet -- and with
    ``bpvf`` chooses every frame's layer for the rate (Algorithm 11 line 5); its layer order
    then uses the first frame only (the temporal term needs frames not yet seen).

    ``StreamEncoder(F, *, method="blocks", step=None, bpvf=None, **options)``. Every call returns
    the bytes ready to send: the stream header with the first frame, one block segment whenever
    ``block`` frames have arrived, and from :meth:`close` the last short block and the frame
    index. The concatenation of all returned bytes is a valid ``.sga`` file. With ``bpvf`` every
    block is coded at the step that meets the rate on its own (per-block rate adaptation).
    Memory is bounded by one block.
    """


class StreamDecoder(_animation.StreamDecoder):
    """Streaming decoder: :meth:`feed` bytes as they arrive; it returns the completed frames.

    ``n_frames`` counts the decoded frames, ``pending_bytes`` what is buffered of an incomplete
    segment (the undecodable rest when a stream is cut).
    """
