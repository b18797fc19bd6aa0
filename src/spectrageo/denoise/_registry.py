"""Registry of static mesh denoisers: ``name -> function(V, F, **options) -> V_denoised``."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError


@dataclass(frozen=True)
class DenoiserInfo:
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
)
_loaded = False


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
        so seams stay closed. Input order and count are kept. False: process ``(V, F)`` as given
        (each seam copy is then a boundary vertex and the seam can open).
    **options
        Keyword options of the method.

    Returns
    -------
    (n, 3) float64 denoised positions, same vertex order.
    """
    info = get(method)
    if weld:
        from ..geometry.repair import weld as weld_mesh

        w = weld_mesh(V, F)
        if w.n_merged:
            out = denoise(
                w.vertices, w.faces, method=method, preset=preset, pre=pre, weld=False, **options
            )
            return w.expand(out)
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
    if pre == "coarse" and method != "tsgsp":
        from .tsgsp import coarse

        V = coarse(V, F, rng=options.get("rng", 0))
    return info.func(V, F, **options)


def warm_up(methods, V, F, *, n_faces: int = 2000) -> None:
    """Run every method once on a small connected piece of ``(V, F)`` (its first ``n_faces``
    faces, re-indexed) so that one-time compilation (numba caches) is not counted in a timed run
    that follows; failures are ignored here (the timed run reports them)."""
    sub = np.asarray(F)[:n_faces]
    used, inv = np.unique(sub, return_inverse=True)
    Vw, Fw = np.asarray(V)[used], inv.reshape(sub.shape)
    for name in methods:
        try:
            denoise(Vw, Fw, method=name)
        except Exception:  # noqa: BLE001, S110 - warm-up only
            pass
