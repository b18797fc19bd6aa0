"""Registry of static mesh denoisers: ``name -> function(V, F, **options) -> V_denoised``."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_positive
from ._guard import (
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


@dataclass(frozen=True)
class DenoiserInfo:
    """A registered denoiser.

    Attributes
    ----------
    name : str
        The method name (``denoise(..., method=name)``).
    func : callable
        ``func(V, F, **options) -> (n, 3) array`` of denoised positions.
    summary : str
        One line describing the method.
    reference : str
        Where the method is defined (thesis section, algorithm or paper).
    presets : tuple of str
        Names accepted by ``denoise(..., preset=...)`` for this method.
    """

    name: str
    func: Callable[..., np.ndarray]
    summary: str
    reference: str
    presets: tuple[str, ...] = ()


_REGISTRY: dict[str, DenoiserInfo] = {}
# modules that register denoisers on import (a missing module is simply skipped)
_PLUGINS = (
    "spectrageo.denoise.smoothing",
    "spectrageo.denoise.bilateral",
    "spectrageo.denoise.gnf",
    "spectrageo.denoise.tsgsp",
    "spectrageo.learn._denoisers",
)
_loaded = False
#: methods whose displacements :func:`denoise` bounds with the trust region (``tsgsp`` bounds its
#: own; the Laplacian and Taubin smoothers are left as defined)
_TRUSTED = ("tsgsp-saliency", "gnf", "bnf", "bilateral")


def register(name: str, *, summary: str, reference: str, presets: tuple[str, ...] = ()):
    """Decorator: register ``func(V, F, **options) -> (n, 3) array`` under ``name``."""

    def deco(func):
        _REGISTRY[name] = DenoiserInfo(name, func, summary, reference, presets)
        return func

    return deco


def _load() -> None:
    global _loaded
    if _loaded:
        return
    for mod in _PLUGINS:
        try:
            importlib.import_module(mod)
        except ModuleNotFoundError as exc:
            if exc.name != mod:
                raise
    _loaded = True


def available() -> list[str]:
    """Names of the registered denoisers, in registration order."""
    _load()
    return list(_REGISTRY)


def get(name: str) -> DenoiserInfo:
    """The registered denoiser ``name``.

    Parameters
    ----------
    name : str
        A name of :func:`available`.

    Returns
    -------
    DenoiserInfo
        Its function, summary, reference and presets.

    Raises
    ------
    InvalidInputError
        If no denoiser of that name is registered.
    """
    _load()
    if name not in _REGISTRY:
        raise InvalidInputError(
            f"unknown denoising method {name!r}; available: {', '.join(_REGISTRY) or 'none'}."
        )
    return _REGISTRY[name]


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

    Parameters
    ----------
    V : (n, 3) float
    F : (m, 3) int
    method : str
        A name from :func:`available`.
    preset : str, optional
        A parameter preset of the method (see ``get(method).presets``); methods without presets
        refuse one.
    pre : None or "coarse"
        ``"coarse"`` first runs the TSGSP coarse step (:func:`spectrageo.denoise.tsgsp.coarse`,
        Fig. 5.7) and hands its result to ``method``. TSGSP always includes that step.
    weld : bool
        Denoise the welded surface: vertices that coincide within
        :data:`spectrageo.geometry.WELD_TOL` of the bounding-box diagonal (UV/normal seam copies,
        unwelded STL corners) are merged first, and every copy receives its merged vertex's result,
        so seams stay closed. Input order and count are kept; a mesh none of whose faces survives
        the merge (every face degenerate) is returned unchanged. False: process ``(V, F)`` as
        given (each seam copy is then a boundary vertex and the seam can open).
    min_noise : float or None
        Do-no-harm gate (:mod:`spectrageo.denoise._guard`): a mesh whose curvature-robust noise
        level (:func:`spectrageo.denoise.noise_level`, noise standard deviation over the median
        16-neighbour patch radius; 0 when the residual passes the detail test of
        :func:`spectrageo.denoise._guard.noise_estimate`, i.e. is spatially correlated surface
        detail rather than white noise) is below ``min_noise`` is returned unchanged, whatever
        the method. Default :data:`spectrageo.denoise._guard.MIN_NOISE` (0.015, chosen on the tuning
        split), except for its sparse impulses (see ``impulses``); ``0`` or a negative value
        disables the gate (and the impulse repair). Before
        the level, a planar tessellation (at least
        :data:`spectrageo.denoise._guard.PLANAR_SHARE` of the face pairs sharing an edge
        coplanar, :func:`spectrageo.denoise._guard.planar_share`, Eq. N9: a CAD export, which
        dense noise would have tilted) is returned unchanged, or with only its sparse impulses
        repaired when ``impulses`` is set, the repair's first pass flags at least 1 % of the
        vertices and the repaired mesh has more coplanar face pairs than the input. A folded
        mesh (at least :data:`spectrageo.denoise._guard.FOLD_SHARE` of the face pairs sharing an
        edge turned by more than 120 degrees against each other, on 50 vertices or more:
        :func:`spectrageo.denoise._guard.is_folded`, Eq. N10; no clean mesh of the tuning data
        comes near it) is never called clean: the gate's tests are skipped and the method runs
        (``tsgsp`` then smooths it with :func:`spectrageo.denoise._guard.unfold`). A coarse mesh
        (:func:`spectrageo.denoise._guard.coarse_shape`, Eqs. N11-N13: a low-poly model whose
        vertices turn by more per edge than noise would, coherently between neighbours) counts as
        clean whatever its level, and a mesh none of whose edges is shared by two faces (separate
        triangles, after welding) is returned unchanged.
    impulses : bool
        Sparse impulses (:func:`spectrageo.denoise._guard.despike`, Eqs. N5-N8, not in the
        thesis): on a mesh the gate calls noisy, isolated spikes are pulled back first when at
        least 1 % of the vertices are such spikes; if the noise level then falls below
        ``min_noise`` the repaired mesh is returned without running the method, otherwise the
        method runs on it (and ``trust`` bounds the displacements from the repaired mesh, with
        the noise deviation measured on it). On a mesh the gate calls clean (not a planar
        tessellation) the repair also runs, and its result is returned when its first pass flags
        at least :data:`spectrageo.denoise._guard.SPIKE_SHARE_QUIET` (2 %) and at least
        :data:`spectrageo.denoise._guard.SPIKE_COUNT_QUIET` (20) of the vertices (impulses on
        organic meshes pass the detail test). A mesh the gate calls noisy whose residual has a
        nearly empty lower tail (ratio of Eq. N4 below
        :data:`spectrageo.denoise._guard.SPARSE_TAIL`, 0.12) and on which the repair flags fewer
        than 1 % of the vertices is returned unchanged (no impulses to repair, and no dense
        noise: module notes of ``_guard``, "Nearly empty lower tail without impulses").
        False: the method sees the input as before, and a mesh the gate calls clean comes back
        unchanged.
    **options
        Keyword options of the method. ``trust`` (noise standard deviations of Eq. 5.15, default
        6; None disables it) bounds every vertex displacement of the feature-preserving
        filters: ``tsgsp`` applies it itself, and for ``tsgsp-saliency``, ``gnf``, ``bnf`` and
        ``bilateral`` this function shortens every displacement longer than ``trust`` noise
        deviations (the Laplacian and Taubin smoothers are left as they are defined).

    Returns
    -------
    (n, 3) float64 denoised positions, same vertex order.
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
    trust = options.pop("trust", TRUST) if method in _TRUSTED else options.get("trust")
    if trust is not None:
        check_positive(trust, "trust")
    from ..geometry.repair import is_soup
    from ..geometry.repair import weld as weld_mesh

    # the gate runs on the input as given (so a clean input comes back bit for bit), except on
    # a triangle soup, which is gated after welding (or refused by the method if welding
    # leaves isolated triangles)
    sigma = None
    share = 0.0  # coplanar face-pair share (Eq. N9) of the mesh the gate measured
    quiet = False  # the gate found no dense noise (level below min_noise)
    tail = 1.0  # lower-tail ratio (Eq. N4) of the mesh the gate measured
    folded = None  # folded mesh (Eq. N10): noisy whatever the gate's other tests say; None:
    # not measured (gate off)
    gated = False  # the gate ran on the input as given
    if min_noise > 0 and not is_soup(F, V.shape[0]):
        gated = True
        folded = is_folded(V, F)
        share = 0.0 if folded else planar_share(V, F)
        if not folded and share < PLANAR_SHARE:
            est = noise_estimate(V, F=F)
            sigma, level, tail = est.sigma, est.level, est.tail
            # a coarse mesh turns by more per edge than noise would, coherently (Eqs. N11-N13)
            if level < min_noise or coarse_shape(V, F).coarse:
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
        # a soup is gated here; a planar mesh's share is measured again on the welded mesh,
        # against which the impulse repair is compared
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
        # no dense noise, but sparse impulses on a surface with detail pass the detail test
        # (N2-N4): pull them back when the repair's first pass flags enough vertices to be
        # impulses rather than the sampling's own outliers (module notes of _guard, "Impulses
        # on meshes the gate calls clean")
        rep = despike(Vw, Fw)
        if rep.share < SPIKE_SHARE_QUIET or round(rep.share * Vw.shape[0]) < SPIKE_COUNT_QUIET:
            return V.copy()
        return w.expand(rep.vertices) if welded else rep.vertices
    if min_noise > 0 and share >= PLANAR_SHARE:
        # a planar tessellation (Eq. N9): no dense noise; only sparse impulses are repaired
        # (the repair is kept only when it makes more face pairs coplanar: a spike pulled back
        # into its plane does, moving a crease or cone apex does not)
        rep = despike(Vw, Fw) if impulses else None
        if rep is None or rep.share < SPIKE_SHARE or planar_share(rep.vertices, Fw) <= share:
            return V.copy()
        return w.expand(rep.vertices) if welded else rep.vertices
    if impulses and min_noise > 0 and sigma is not None:
        rep = despike(Vw, Fw)
        if rep.share < SPIKE_SHARE and tail < SPARSE_TAIL:
            # nearly empty lower tail (Eq. N4) but no impulses to repair: the patches that fit
            # exactly are the surface's own (module notes of _guard, "Nearly empty lower tail
            # without impulses")
            return V.copy()
        if rep.share >= SPIKE_SHARE:
            sigma_r, level_r = noise_sigma(rep.vertices, F=Fw)
            if level_r < min_noise:
                out = rep.vertices  # the impulses were the noise
                return w.expand(out) if welded else out
            Vw, sigma = rep.vertices, sigma_r
    out = _run(info, Vw, Fw, pre=pre, trust=trust, sigma=sigma, folded=folded, options=options)
    return w.expand(out) if welded else out


def _run(info, V, F, *, pre, trust, sigma, folded, options) -> np.ndarray:
    """The method itself, with the coarse pre-step and the trust region of :func:`denoise`.
    ``sigma`` and ``folded`` are the noise estimate and the folded-mesh decision already made by
    the gate (None: made here, by the method)."""
    if info.name == "tsgsp" and sigma is not None:
        options = {**options, "sigma_z": sigma}
    if info.name == "tsgsp" and folded is not None:
        options = {**options, "folded": folded}
    V0 = V
    if pre == "coarse" and info.name != "tsgsp":
        from .tsgsp import coarse

        V = coarse(V, F, rng=options.get("rng", 0))
    out = info.func(V, F, **options)
    if info.name not in _TRUSTED or trust is None:
        return out
    if sigma is None:
        sigma = noise_sigma(V0, F=F)[0]
    return apply_trust(V0, out, float(trust) * sigma)


def warm_up(methods, V, F, *, n_faces: int = 2000) -> None:
    """Run every method once on a small connected piece of ``(V, F)`` (``n_faces`` faces reached
    by a breadth-first walk over shared edges from face 0, re-indexed) so that one-time
    compilation (numba caches) is not counted in a timed run that follows; failures are ignored
    here (the timed run reports them). (The first ``n_faces`` faces of a file are not always
    connected: on Block0.4 they were a soup, the warm-up failed and the first timed run paid
    12 s of compilation.)"""
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
