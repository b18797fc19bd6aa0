"""Compression of triangle meshes (``.sgc``) and mesh animations (``.sga``), thesis Section 5.2.

* :func:`encode` / :func:`decode` / :func:`info` for static meshes: ``"spectral"`` (block
  spectral coding on overlapped submeshes, Algorithms 6-8, Eq. 5.42-5.45; progressive),
  ``"feature"`` (feature-aware high-pass quantisation, Algorithm 9, Eq. 5.53-5.54) and
  ``"saliency"`` (saliency classes choose the deltas sent, Algorithm 10) and ``"predictive"``
  (uniform grid, parallelogram prediction, adaptive range coding: :mod:`._predictive`). The
  default, ``method="auto"``, keeps the smaller of ``"predictive"`` and ``"spectral"`` at the
  target given (``"spectral"`` without one).
* :func:`encode_animation` / :func:`decode_animation` / :func:`info_animation`,
  :class:`StreamEncoder` / :class:`StreamDecoder` for animations (Sections 5.2.2 and 5.2.4).
* Rate control: ``bpv=`` / ``bpvf=`` (whole file) or ``error=``, met within 5 % by bisection of
  the quantisation step; ``max_error=`` bounds the largest vertex displacement; ``feature`` and ``saliency`` also choose their level of detail (see
  :mod:`spectrageo.compress._feature`).
* Vertex and face order are kept exactly unless ``reorder=True`` (:func:`info` then reports
  ``"reordered": true``).

Damaged, truncated or foreign data raise :class:`~spectrageo.InvalidInputError`; decoders give
the same bits on every machine (docs/decisions.md#deterministic-decoders).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._progress import activity
from .._validation import as_faces, as_points, check_choice
from . import _connectivity, _container, _sga
from ._rate import RATE_TOLERANCE as RATE_TOLERANCE
from ._rate import STEP_MAX, STEP_MIN, bisect_step, check_connectivity_floor, error_step
from ._sga_format import ALL_METHODS, is_animation

__all__ = [
    "ANIMATION_METHODS",
    "AUTO_SPECTRAL_BPV",
    "ENCODE_METHODS",
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

METHODS = ("spectral", "feature", "saliency", "predictive")
#: what :func:`encode` takes: a file's method, or ``"auto"`` (the default)
ENCODE_METHODS = ("auto", *METHODS)
#: ``"auto"`` tries ``"spectral"`` when the ``"predictive"`` file's geometry takes at most this many
#: bits per vertex (docs/decisions.md#codec-auto)
AUTO_SPECTRAL_BPV = 8.0
TAG_CONNECTIVITY = 1
#: relative width at which the ``max_error`` bisection of the non-predictive methods stops: a
#: numerical tolerance (files within about 0.4 % of the largest step's), not a tuned default
#: (docs/decisions.md#codec-auto)
MAX_ERROR_STEP_TOL = 0.002
#: the ``max_error`` search goes on past a failing step while the largest deviation stays within
#: this factor of the bound, and for at most ``LADDER_FAILS`` failing steps in a row: search
#: effort, not tuned defaults (docs/decisions.md#codec-max-error-ladder)
LADDER_SLACK = 1.1
LADDER_FAILS = 4

#: default quantisation step (fraction of the bounding-box diagonal) when no rate is requested
DEFAULT_STEP = {"spectral": 1e-3, "feature": 4e-4, "saliency": 4e-4, "predictive": 5e-4}


def _module(method: str):
    if method == "spectral":
        from . import _spectral as m
    elif method == "predictive":
        from . import _predictive as m
    else:
        from . import _feature as m
    return m


def _check_rate(bpv, error, max_error=None) -> None:
    if sum(x is not None for x in (bpv, error, max_error)) > 1:
        raise InvalidInputError("give at most one of `bpv`, `error` and `max_error`.")
    for name, v in (("bpv", bpv), ("error", error), ("max_error", max_error)):
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
    method: str = "auto",
    bpv: float | None = None,
    error: float | None = None,
    reorder: bool = False,
    step: float | None = None,
    max_error: float | None = None,
    **options: Any,
) -> bytes:
    """Compress a triangle mesh into ``.sgc`` bytes.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
        Every vertex index in ``0..n-1``; vertices that no face uses are coded too.
    method : {"auto", "spectral", "feature", "saliency", "predictive"}
        ``"auto"`` (default): with a target, the smaller file of ``"predictive"`` and
        ``"spectral"`` (at ``bpv``: the smaller RMS error); ``"spectral"`` is tried only when
        the ``"predictive"`` geometry takes at most :data:`AUTO_SPECTRAL_BPV` bits per vertex.
        Without a target, with ``step`` or with options: ``"spectral"`` (progressive).
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
        Quantisation step as a fraction of the diagonal, used when no target is given (default
        :data:`DEFAULT_STEP`).
    max_error : float, optional
        Bound on the largest vertex displacement ``max ||v - v'||`` over the diagonal, hence on
        the symmetric vertex-to-surface Hausdorff distance. ``predictive`` keeps every coordinate
        within ``max_error / sqrt(3)``; the other methods take the largest step that keeps it.
    **options
        Method parameters (with ``"auto"``: ``"spectral"``'s). ``spectral``: ``submesh_size``
        (300), ``overlap`` (0.1), ``k`` (dictionary size per submesh, default
        ``submesh_size``: the quantiser, not a cut-off, drops the high frequencies), ``basis``
        ("oi", "exact", "doi"), ``zeta`` (4), ``n_iter`` (1), ``eps`` (DOI residual
        threshold), ``seed`` (0). ``feature`` / ``saliency``: see
        :mod:`spectrageo.compress._feature`.

    Returns
    -------
    bytes
        The ``.sgc`` file content.

    Raises
    ------
    InvalidInputError
        Bad arrays or arguments, or a target that the method (with ``"auto"``: neither method)
        reaches.

    Examples
    --------
    >>> from spectrageo import datasets  # doctest: +SKIP
    >>> mesh = datasets.fandisk()  # doctest: +SKIP
    >>> data = encode(mesh.vertices, mesh.faces, max_error=1e-4, reorder=True)  # doctest: +SKIP
    >>> info(data)["method"]  # doctest: +SKIP
    'predictive'
    """
    check_choice(method, "method", ENCODE_METHODS)
    _check_rate(bpv, error, max_error)
    if step is not None and (bpv is not None or error is not None or max_error is not None):
        raise InvalidInputError("`step` cannot be combined with `bpv`, `error` or `max_error`.")
    if step is not None and not (isinstance(step, int | float) and STEP_MIN <= step <= STEP_MAX):
        raise InvalidInputError(f"`step` must be in [{STEP_MIN}, {STEP_MAX}]; got {step!r}.")
    targeted = bpv is not None or error is not None or max_error is not None
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    if V.shape[0] > _container.MAX_COUNT or F.shape[0] > _container.MAX_COUNT:
        raise InvalidInputError("the mesh is too large for the .sgc format (2**28 elements).")
    if not isinstance(reorder, bool | np.bool_):
        raise InvalidInputError(f"`reorder` must be True or False; got {reorder!r}.")
    if reorder:
        V, F, _perm, conn = _connectivity.reorder_coded(V, F)
    else:
        conn = _connectivity.encode_faces(F)
    lo, hi = V.min(axis=0), V.max(axis=0)
    diag = float(np.linalg.norm(hi - lo))
    # rounded to what the header stores exactly (docs/decisions.md#codec-container-v4)
    origin, scale = _container.compact_frame(0.5 * (lo + hi), diag if diag > 0 else 1.0)
    prep = _Prepared(V, F, (V - np.asarray(origin)) / scale, origin, scale, conn, bool(reorder))
    if bpv is not None:  # a target below the connectivity's share is refused before any search
        check_connectivity_floor(float(bpv), len(conn), V.shape[0], bool(reorder))
    target = _Target(bpv, error, max_error, step)
    if method != "auto":
        return _encode_one(prep, method, target, options)[0]
    if not targeted or options:  # method options with "auto" are spectral's, as they were
        return _encode_one(prep, "spectral", target, options)[0]
    return _encode_auto(prep, target)


@dataclass(frozen=True)
class _Prepared:
    """A mesh ready for a codec: (reordered) arrays, the normalised coordinates ``X`` in the
    header's frame, and the connectivity chunk."""

    V: np.ndarray
    F: np.ndarray
    X: np.ndarray
    origin: tuple
    scale: float
    conn: bytes
    reorder: bool


@dataclass(frozen=True)
class _Target:
    bpv: float | None
    error: float | None
    max_error: float | None
    step: float | None


def _encode_one(prep: _Prepared, method: str, target: _Target, options: dict) -> tuple:
    """One method's file for ``target``: ``(bytes, plan, step)``."""
    X, n = prep.X, prep.V.shape[0]
    bpv, error, max_error = target.bpv, target.error, target.max_error
    mod = _module(method)
    plan = mod.make_plan(X, prep.F, method, options)

    def build(s: float, p=plan) -> bytes:
        c = _container.Container(
            method,
            n,
            prep.F.shape[0],
            tuple(float(x) for x in prep.origin),
            float(prep.scale),
            p.params(s),
            prep.reorder,
            [(TAG_CONNECTIVITY, prep.conn), *p.chunks(s)],
        )
        return c.to_bytes()

    if max_error is not None:
        s = _max_error_step(plan, X, float(max_error), method)
        return build(s), plan, s
    if bpv is None and error is None:
        s = DEFAULT_STEP[method] if target.step is None else float(target.step)
        return build(s), plan, s
    # the delta codecs choose their level of detail (Algorithm 9 step 5, Algorithm 10 steps
    # 4-5) unless it is given
    given = {"feature": "feature_fraction", "saliency": "class_keep"}.get(method)
    chosen = given is not None and not {given, "ratio", "mask"} & set(options)
    plans = plan.levels() if chosen else [plan]

    best, failure = None, None
    for p in plans:
        try:
            if bpv is not None:
                s, data = bisect_step(
                    lambda s, p=p: (8.0 * len(build(s, p)) / n, None),
                    float(bpv),
                    increasing=False,
                    what="bpv",
                )
                key = _rms(p, s, X) if len(plans) > 1 else 0.0
            else:
                s = error_step(lambda s, p=p: _rms(p, s, X), float(error), method)
                key = len(build(s, p)) if len(plans) > 1 else 0
        except InvalidInputError as exc:
            failure = exc  # the last level (uniform) reaches the widest range of requests
            continue
        if best is None or key < best[0]:
            best = (key, p, s)
    if best is None:
        raise failure
    return build(best[2], best[1]), best[1], best[2]


def _rms(plan, s, X: np.ndarray) -> float:
    """RMS vertex error of ``plan`` at step ``s`` (``None``: unquantised, the method's floor)."""
    d = plan.reconstruct(s) - X
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def _encode_auto(prep: _Prepared, target: _Target) -> bytes:
    """``method="auto"`` with a target: ``predictive``, then ``spectral`` where it may be smaller.

    ``spectral`` is tried when the ``predictive`` file's geometry (or, at ``bpv``, the target's
    share beyond the connectivity) takes at most :data:`AUTO_SPECTRAL_BPV` bits per vertex, or
    when ``predictive`` cannot serve the target. Kept: the smaller file at ``error`` /
    ``max_error``; at ``bpv`` the smaller RMS vertex error (ties to ``predictive``).
    """
    n = prep.V.shape[0]
    conn_bpv = 8.0 * len(prep.conn) / n
    found, failure = [], None
    try:
        found.append(_encode_one(prep, "predictive", target, {}))
    except InvalidInputError as exc:
        failure = exc
    if target.bpv is not None:
        geometry_bpv = float(target.bpv) - conn_bpv
    else:
        geometry_bpv = 8.0 * len(found[0][0]) / n - conn_bpv if found else 0.0
    if not found or geometry_bpv <= AUTO_SPECTRAL_BPV:
        try:
            found.append(_encode_one(prep, "spectral", target, {}))
        except InvalidInputError as exc:
            failure = failure or exc
    if not found:
        raise failure
    if target.bpv is not None:
        return min(found, key=lambda f: _rms(f[1], f[2], prep.X))[0]
    return min(found, key=lambda f: len(f[0]))[0]


def _max_error_step(plan, X: np.ndarray, bound: float, method: str) -> float:
    """The step for ``max_error``: a step whose decoded vertices all lie within ``bound`` of the
    input, within :data:`MAX_ERROR_STEP_TOL` (relative) of a larger step that does not
    (``predictive`` computes its step directly; the others search, :func:`_ladder_step`)."""

    def worst(s) -> float:
        d = plan.reconstruct(s) - X
        return float(np.sqrt(np.max(np.sum(d * d, axis=1)))) if d.size else 0.0

    if method == "predictive":
        return plan.for_max_error(bound)
    with activity("compress: searching the step for `max_error`"):
        return _search_max_error(worst, bound, method)


def _search_max_error(worst, bound: float, method: str) -> float:
    """The finest step's check, the linear guess, then :func:`_ladder_step`."""
    w0 = worst(STEP_MIN)
    if w0 > bound:
        raise InvalidInputError(
            f"`max_error` = {bound:g} is below what method {method!r} reaches here (largest "
            f"deviation {max(worst(None), w0):.3g} at the finest step); use "
            "method='predictive', which reaches any bound."
        )
    s1 = min(max(bound, STEP_MIN), STEP_MAX)
    w1 = worst(s1)
    slope = (w1 - w0) / (s1 - STEP_MIN) if s1 > STEP_MIN else 0.0
    guess = STEP_MIN + (bound - w0) / slope if slope > 0 else STEP_MAX
    return _ladder_step(worst, bound, min(max(guess, STEP_MIN), STEP_MAX))


def _ladder_step(worst, bound: float, s: float) -> float:
    """The search of :func:`_max_error_step` from ``s`` (``worst(STEP_MIN) <= bound``): down to a
    passing step, up past isolated failures (:data:`LADDER_SLACK`), then log-bisection
    (docs/decisions.md#codec-max-error-ladder)."""
    q = 1.0 + 16.0 * MAX_ERROR_STEP_TOL
    lo, hi, r = None, None, q
    while lo is None:  # down to a passing step
        if s <= STEP_MIN or worst(s) <= bound:
            lo = max(s, STEP_MIN)
        else:
            hi, s, r = s, max(s / r, STEP_MIN), r * r
    if hi is None:  # up while the deviation stays near the bound
        t, r, fails = lo, q, 0
        while t < STEP_MAX and fails < LADDER_FAILS:
            t = min(t * r, STEP_MAX)
            w = worst(t)
            if w <= bound:
                lo, hi, r, fails = t, None, min(r * r, 2.0), 0
                continue
            hi, r, fails = hi or t, q, fails + 1
            if w > LADDER_SLACK * bound:
                break
        if hi is None:
            return STEP_MAX
    lo, hi = math.log(lo), math.log(hi)
    while hi - lo > math.log1p(MAX_ERROR_STEP_TOL):
        mid = 0.5 * (lo + hi)
        if worst(math.exp(mid)) <= bound:
            lo = mid
        else:
            hi = mid
    return math.exp(lo)


def _parse(data, partial: bool):
    if is_animation(data):
        raise InvalidInputError(
            "this is a compressed animation (.sga); use spectrageo.compress.decode_animation."
        )
    c = _container.parse(data, partial=partial)
    if not c.chunks or c.chunks[0][0] != TAG_CONNECTIVITY:
        raise InvalidInputError(".sgc data lacks its connectivity chunk.")
    return c


def decode(data, *, partial: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Decompress ``.sgc`` bytes into ``(V, F)``: (n, 3) float64 and (m, 3) int64.

    ``partial=True`` accepts a prefix of a progressive file: complete geometry layers are used, the
    missing ones taken as zero (a smoother, coarser mesh); otherwise a truncated file is an error.

    Raises
    ------
    InvalidInputError
        Not an ``.sgc`` file, unsupported version, checksum mismatch, chunks out of place,
        truncated, malformed, or declared counts whose decoding would exceed the memory cap
        (:func:`spectrageo.io._common.max_bytes`).
    """
    c = _parse(data, partial)
    n, m = c.n_vertices, c.n_faces
    _container.check_memory(c.method, n, m, ".sgc header")
    F = _connectivity.decode_faces(c.chunks[0][1], n, m)
    mod = _module(c.method)
    X = mod.decode(c.params, c.chunks[1:], F, n, c.method, complete=c.complete)
    V = X * c.scale + np.asarray(c.origin)
    if not np.isfinite(V).all():
        raise InvalidInputError(".sgc data decodes to non-finite coordinates (corrupted).")
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
    if c.method in ("feature", "saliency"):
        params["sent_share"] = round(mod.sent_share(c.chunks[1:], c.n_vertices), 6)
    return {
        "format": "sgc",
        "version": c.version,
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
ANIMATION_METHODS = ALL_METHODS


def encode_animation(
    frames,
    F,
    *,
    method: str = "pca-pred",
    bpvf: float | None = None,
    error: float | None = None,
    step: float | None = None,
    **options: Any,
) -> bytes:
    """Compress a mesh animation with fixed connectivity into ``.sga`` bytes (Section 5.2.2).

    Delta coordinates projected on eigen-trajectories (Eq. 5.46-5.52, :mod:`._animation`), the
    layered streaming codec (``"layered"``, Section 5.2.4, Algorithm 11, :mod:`._layered`), or
    ``"pca-spectral"``, eigen-trajectories in the partitioned GFT basis (:mod:`._pca_spectral`).

    Parameters
    ----------
    frames : (T, n, 3) float or MeshAnimation
    F : (m, 3) int
        Shared faces; vertex order and faces are kept exactly.
    method : {"pca-pred", "pca", "pca-q", "pca-qs", "pca-qp", "blocks", "pca-spectral", "layered"}
        ``"pca-pred"`` (default): trajectory PCA with the coefficients predicted along the mesh
        (:mod:`._pca_pred`; not of the thesis), the smallest files; its step defaults to 2.5e-4.
    bpvf : float, optional
        Target size of the whole file in bits per vertex per frame (met within 5 %).
    error : float, optional
        Target KG error (in percent, :func:`spectrageo.metrics.kg_error`), met within 5 %.
    step : float, optional
        Quantisation step of the delta-coordinate projections (fraction of the bounding-box
        diagonal; default 2e-4) when no target is given; for ``pca`` the number of kept
        coefficients per coordinate.
    **options
        ``block`` (frames per block of ``blocks``, 16), ``anchors`` (fraction of anchor vertices
        of pca-qs / pca-qp / blocks, 0.01), ``anchor_ratio`` (anchor step / step, 0.5),
        ``weight`` (anchor weight in Eq. 5.51, 1), ``basis`` ("oi" or "exact"), ``n_iter`` (2),
        ``rd`` (row-dropping strength, 1); ``pca-spectral`` accepts and ignores them.
        ``pca-pred``: ``block`` (frames per block, 512) and ``reorder`` (False; True codes the
        vertices and faces in the connectivity coder's order, as the static ``reorder``).
        ``layered``: ``layer`` (fraction of the vertices sent per frame, 0.1), ``refresh`` (a
        refresh frame every that many frames, 16; 0 = never) and ``fine`` (the RPCA/ISVD fine
        reconstruction, off); its ``step`` (default 1e-3) is a fraction of twice the first
        frame's diagonal.

    Returns
    -------
    bytes
        The ``.sga`` file content (stream header, one segment per block, frame index).
    """
    return _sga.encode_animation(
        frames, F, method=method, bpvf=bpvf, error=error, step=step, **options
    )


def decode_animation(data, *, partial: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Decompress ``.sga`` bytes into ``(frames, F)``: (T, n, 3) float64 and (m, 3) int64.

    ``partial=True`` accepts a truncated file (one without its trailing frame index included)
    and returns the frames of every complete block (compare ``frames.shape[0]`` with
    :func:`info_animation` of the full file, or use :class:`StreamDecoder`, to know what is
    missing). Damaged data, and counts whose decoding would exceed the memory cap, raise
    :class:`~spectrageo.InvalidInputError`.
    """
    return _sga.decode_animation(data, partial=partial)


def info_animation(data) -> dict:
    """Header summary of ``.sga`` bytes: method, frames, counts, bpvf, blocks, parameters."""
    return _sga.info_animation(data)


class StreamEncoder(_sga.StreamEncoder):
    """Streaming encoder (``pca-pred``, ``blocks`` or ``layered``): :meth:`push` one frame at a
    time, then :meth:`close`.

    ``StreamEncoder(F, *, method="pca-pred", step=None, bpvf=None, **options)``. Every call
    returns the bytes ready to send; their concatenation is a valid ``.sga`` file. ``pca-pred``
    and ``blocks`` emit one segment per ``block`` frames (default 16; with ``bpvf``, each block at
    the step that meets the rate), hold one block in memory and normalise by twice the first
    frame's box; ``pca-pred`` takes ``reorder=True`` as :func:`encode_animation` does (the order
    from the first frame). ``layered`` emits one segment per frame, the header and the whole
    first frame with the first push; with ``bpvf`` it chooses every frame's layer (Algorithm 11
    line 5) and its layer order uses the first frame only.
    """


class StreamDecoder(_sga.StreamDecoder):
    """Streaming decoder: :meth:`feed` bytes as they arrive; it returns the completed frames.

    ``n_frames`` counts the decoded frames, ``pending_bytes`` what is buffered of an incomplete
    segment (the undecodable rest when a stream is cut).
    """
