"""Plugins declared as package entry points, and package names imported on first use.

A lower layer keeps a registry (``io``'s format table, ``denoise``'s method table); a higher layer
fills it by declaring an entry point in ``pyproject.toml``::

    [project.entry-points."spectrageo.formats"]
    sgc = "spectrageo.compress._sgc_io:register"

The lower layer calls :func:`load_plugins` with its group name when a lookup misses, so it never
imports the layer above, and a third-party package can register its own readers or methods the
same way. :func:`lazy_exports` lets a package ``__init__`` import its public names only when one
is used, so that a command imports only the modules it runs.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from ._errors import SpectrageoError

_LOADED: set[str] = set()


def load_plugins(group: str) -> None:
    """Call the ``register()`` function of every entry point in ``group``, once per process.

    Parameters
    ----------
    group : str
        Entry-point group, e.g. ``"spectrageo.formats"`` or ``"spectrageo.denoisers"``.

    Raises
    ------
    SpectrageoError
        If a plugin fails to import or to register; the message names the entry point.
    """
    if group in _LOADED:
        return
    from importlib.metadata import entry_points

    _LOADED.add(group)
    for ep in sorted(entry_points(group=group), key=lambda e: e.name):
        try:
            register = ep.load()
            register()
        except Exception as exc:  # a broken plugin is an error, named, never skipped
            _LOADED.discard(group)
            raise SpectrageoError(
                f"plugin {ep.name!r} ({ep.value}) of {group!r} failed: {exc}"
            ) from exc


def lazy_exports(
    package: str, exports: dict[str, str], eager: tuple[str, ...] = ()
) -> tuple[Callable, Callable]:
    """``(__getattr__, __dir__)`` of a package whose names are imported on first access (PEP 562).

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : dict
        Public name -> submodule that defines it, relative (``".neighbors"``).
    eager : tuple of str
        Public names the package binds at import; listed by ``__dir__`` too.

    Returns
    -------
    tuple of callable
        Module-level ``__getattr__`` (imports the submodule, caches the value in the package)
        and ``__dir__`` (the public names).
    """
    names = sorted([*exports, *eager])

    def __getattr__(name: str):
        try:
            module = exports[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        value = getattr(importlib.import_module(module, package), name)
        setattr(importlib.import_module(package), name, value)
        return value

    def __dir__() -> list[str]:
        return names

    return __getattr__, __dir__
