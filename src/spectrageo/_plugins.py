"""Plugins declared as package entry points, loaded once on first need.

A lower layer keeps a registry (``io``'s format table, ``denoise``'s method table); a higher layer
fills it by declaring an entry point in ``pyproject.toml``::

    [project.entry-points."spectrageo.formats"]
    sgc = "spectrageo.compress._sgc_io:register"

The lower layer calls :func:`load_plugins` with its group name when a lookup misses, so it never
imports the layer above, and a third-party package can register its own readers or methods the
same way.
"""

from __future__ import annotations

from importlib.metadata import entry_points

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
