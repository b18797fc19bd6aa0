"""Dispatch of the static denoisers: the do-no-harm gate, welding, the trust region, warm-up."""

from __future__ import annotations

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_positive
from ._guard import (
    FOLD_MIN_VERTICES,
    MIN_NOISE,
    PLANAR_SHARE,
    SPARSE_TAIL,
    SPIKE_COUNT_QUIET,
    SPIKE_SHARE,
    SPIKE_SHARE_QUIET,
    TRUST,
    apply_trust,
    coarse_shape,
    despike,
    has_shared_edge,
    is_folded,
    noise_estimate,
    noise_sigma,
    planar_share,
)
from ._table import DenoiserInfo, available, get, register
from ._tsgsp_coarse import coarse

__all__ = ["DenoiserInfo", "available", "denoise", "get", "register", "warm_up"]


def denoise(
    V,
    F,
    *,
    method: str = "tsgsp",
    preset: str | None = None,
    pre: str | None = None,
    weld: bool = True,
    min_noise: float | None = None,
    impulses: bool = True,
    **options,
) -> np.ndarray:
    """Denoise the vertex positions of mesh ``(V, F)`` with the registered ``method``.

    A do-no-harm gate (:mod:`~spectrageo.denoise._guard`, Eqs. N1-N13, not in the thesis) first
    returns planar tessellations, meshes without noise or with detail only, and coarse low-poly
    meshes unchanged, apart from a repair of sparse impulses; see docs/decisions.md#denoise-gate-level.

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    method : str
        A name from :func:`available`.
    preset : str, optional
        One of ``get(method).presets``.
    pre : None or "coarse"
        Run TSGSP's coarse step (Algorithm 1) first.
    weld : bool
        Merge coincident vertices first; every copy gets its merged result.
    min_noise : float, optional
        Gate level (default ``MIN_NOISE``); ``<= 0`` disables the gate.
    impulses : bool
        Repair sparse impulses (docs/decisions.md#denoise-impulse-repair).
    **options
        Options of the method; ``trust`` bounds the displacements of trusted methods in noise
        deviations (default 6; docs/decisions.md#denoise-trust-region).

    Returns
    -------
    (n, 3) float64
    """
    info = get(method)
    if min_noise is None:
        min_noise = MIN_NOISE
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    if pre is not None and pre != "coarse":
        raise InvalidInputError(f"`pre` must be None or 'coarse'; got {pre!r}.")
    if preset is not None:
        if not info.presets:
            raise InvalidInputError(f"method {method!r} has no presets; got `preset`={preset!r}.")
        if preset not in info.presets:
            raise InvalidInputError(
                f"`preset` must be one of {', '.join(info.presets)} for {method!r}; got {preset!r}."
            )
        options["preset"] = preset
    trust = options.pop("trust", TRUST) if info.trusted else options.get("trust")
    if trust is not None:
        check_positive(trust, "trust")
    args = dict(pre=pre, min_noise=min_noise, impulses=impulses, trust=trust, options=options)
    out = _gated(info, V, F, weld=weld, **args)
    if min_noise > 0 and not np.array_equal(out, V):
        out = _keep_clean_parts(info, V, F, out, weld=weld, **args)
    return out


def _gated(info, V, F, *, pre, weld, min_noise, impulses, trust, options) -> np.ndarray:
    """The do-no-harm gate (Eqs. N1-N13) and the method, on the whole mesh ``(V, F)``."""
    from ..geometry.repair import degenerate_faces, is_soup
    from ..geometry.repair import weld as weld_mesh

    if degenerate_faces(V, F).all():  # no face of non-zero area: nothing to filter
        return V.copy()

    # the gate runs on the input as given (a clean input comes back bit for bit), except on a
    # triangle soup, which is gated after welding
    sigma = None
    share = 0.0  # coplanar face-pair share (Eq. N9) of the mesh the gate measured
    quiet = False  # the gate found no dense noise (level below min_noise)
    tail = 1.0  # lower-tail ratio (Eq. N4) of the mesh the gate measured
    folded = None  # folded mesh (Eq. N10); None: not measured (gate off)
    gated = False  # the gate ran on the input as given
    if min_noise > 0 and not is_soup(F, V.shape[0]):
        gated = True
        folded = is_folded(V, F)
        share = 0.0 if folded else planar_share(V, F)
        if not folded and share < PLANAR_SHARE:
            est = noise_estimate(V, F=F)
            sigma, level, tail = est.sigma, est.level, est.tail
            if level < min_noise or coarse_shape(V, F).coarse:  # Eqs. N11-N13
                if not impulses:
                    return V.copy()  # no noise found: nothing to remove
                quiet = True
    w = weld_mesh(V, F) if weld else None
    welded = w is not None and w.n_merged > 0
    Vw, Fw = (w.vertices, w.faces) if welded else (V, F)
    if Fw.shape[0] == 0:
        return V.copy()  # every face collapsed when coincident vertices were merged
    if min_noise > 0 and not has_shared_edge(Fw):
        return V.copy()  # separate triangles: no filter has a neighbourhood to work with
    if min_noise > 0 and (not gated or (welded and sigma is None and not folded)):
        # a soup is gated here; a planar mesh's share is measured again on the welded mesh
        folded = is_folded(Vw, Fw)
        share = 0.0 if folded else planar_share(Vw, Fw)
        if not folded and share < PLANAR_SHARE:
            est = noise_estimate(Vw, F=Fw)
            sigma, level, tail = est.sigma, est.level, est.tail
            if level < min_noise or coarse_shape(Vw, Fw).coarse:
                if not impulses:
                    return V.copy()
                quiet = True
    if quiet:
        # sparse impulses on a surface with detail pass the detail test (N2-N4)
        rep = despike(Vw, Fw)
        if rep.share < SPIKE_SHARE_QUIET or round(rep.share * Vw.shape[0]) < SPIKE_COUNT_QUIET:
            return V.copy()
        return w.expand(rep.vertices) if welded else rep.vertices
    if min_noise > 0 and share >= PLANAR_SHARE:
        # a planar tessellation (Eq. N9): only sparse impulses are repaired, and the repair is
        # kept only when it makes more face pairs coplanar
        rep = despike(Vw, Fw) if impulses else None
        if rep is None or rep.share < SPIKE_SHARE or planar_share(rep.vertices, Fw) <= share:
            return V.copy()
        return w.expand(rep.vertices) if welded else rep.vertices
    if impulses and min_noise > 0 and sigma is not None:
        rep = despike(Vw, Fw)
        if rep.share < SPIKE_SHARE and tail < SPARSE_TAIL:
            return V.copy()  # nearly empty lower tail (Eq. N4) without impulses
        if rep.share >= SPIKE_SHARE:
            sigma_r, level_r = noise_sigma(rep.vertices, F=Fw)
            if level_r < min_noise:
                out = rep.vertices  # the impulses were the noise
                return w.expand(out) if welded else out
            Vw, sigma = rep.vertices, sigma_r
    out = _run(info, Vw, Fw, pre=pre, trust=trust, sigma=sigma, folded=folded, options=options)
    return w.expand(out) if welded else out


def _part_is_clean(V, F, min_noise: float) -> bool:
    """The gate's verdict on one part alone: planar (Eq. N9), or below ``min_noise`` or coarse
    (Eqs. N11-N13), and not folded (Eq. N10)."""
    if is_folded(V, F):
        return False
    if planar_share(V, F) >= PLANAR_SHARE:
        return True
    return noise_estimate(V, F=F).level < min_noise or coarse_shape(V, F).coarse


def _keep_clean_parts(info, V, F, out, *, weld, **args) -> np.ndarray:
    """Parts (components of the welded mesh of at least ``FOLD_MIN_VERTICES`` vertices, the floor
    under which Eq. N10 counts no folds; two or more of them) that the gate calls clean on their own get the result of denoising them alone,
    which is the input itself unless sparse impulses were repaired; the other vertices keep
    ``out``. See docs/decisions.md#denoise-gate-parts."""
    from scipy.sparse.csgraph import connected_components

    from ..geometry.repair import weld as weld_mesh
    from ..graph import adjacency_matrix

    w = weld_mesh(V, F) if weld else None
    Vw, Fw = (w.vertices, w.faces) if w is not None else (V, F)
    imap = w.index_map if w is not None else np.arange(V.shape[0])
    if Fw.shape[0] == 0:
        return out
    _, lab = connected_components(adjacency_matrix(Fw, Vw.shape[0]), directed=False)
    used = np.zeros(Vw.shape[0], dtype=bool)
    used[Fw.ravel()] = True
    sizes = np.bincount(lab[used], minlength=lab.max() + 1)
    parts = np.flatnonzero(sizes >= FOLD_MIN_VERTICES)
    if parts.size < 2:
        return out
    out = np.array(out, dtype=np.float64, copy=True)
    face_part = lab[Fw[:, 0]]
    for c in parts:
        keep = np.flatnonzero((lab == c) & used)
        Fc = np.searchsorted(keep, Fw[face_part == c])
        Vc = Vw[keep]
        if not _part_is_clean(Vc, Fc, args["min_noise"]):
            continue
        alone = _gated(info, Vc, Fc, weld=False, **args)
        mine = np.flatnonzero(lab[imap] == c)
        if np.array_equal(alone, Vc):
            out[mine] = V[mine]
        else:
            out[mine] = alone[np.searchsorted(keep, imap[mine])]
    return out


def _run(info, V, F, *, pre, trust, sigma, folded, options) -> np.ndarray:
    """The method with the coarse pre-step and the trust region (``sigma``, ``folded``: the gate's)."""
    if info.name == "tsgsp" and (sigma is not None or folded is not None):
        from .tsgsp import GateMeasures

        options = {**options, "measured": GateMeasures(sigma=sigma, folded=folded)}
    V0 = V
    if pre == "coarse" and info.name != "tsgsp":
        V = coarse(V, F, rng=options.get("rng", 0)).vertices
    out = info.func(V, F, **options)
    if not info.trusted or trust is None:
        return out
    if sigma is None:
        sigma = noise_sigma(V0, F=F)[0]
    return apply_trust(V0, out, float(trust) * sigma)


def warm_up(methods, V, F, *, n_faces: int = 2000) -> None:
    """Run every method once on a connected piece of ``(V, F)`` (``n_faces`` faces) so that
    compilation is not timed; failures are left to the timed run."""
    from scipy.sparse.csgraph import breadth_first_order

    from ..graph import face_adjacency

    F = np.asarray(F)
    if F.ndim != 2 or F.shape[0] == 0:
        return
    order = breadth_first_order(face_adjacency(F), 0, directed=False, return_predecessors=False)
    sub = F[np.sort(order[:n_faces])]
    used, inv = np.unique(sub, return_inverse=True)
    Vw, Fw = np.asarray(V)[used], inv.reshape(sub.shape)
    for name in methods:
        try:
            denoise(Vw, Fw, method=name)
        except Exception:  # noqa: BLE001, S110 - warm-up only
            pass
