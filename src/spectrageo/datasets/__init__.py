"""Embedded models and access to the shared benchmark data.

* :func:`fandisk` returns the CC0 fandisk mesh (6475 vertices, 12946 faces) shipped in the package
  (CGAL data, CC0), the default model of ``spectrageo demo``.
* :func:`data_dir` locates the shared data folder: the ``SPECTRAGEO_DATA`` environment variable,
  else ``../shared/data`` relative to the current directory or to the source checkout.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from ..geometry.data import Mesh

_HERE = Path(__file__).resolve()


def fandisk_path() -> Path:
    """Path of the embedded fandisk ``.off`` file."""
    return Path(str(resources.files(__package__).joinpath("fandisk.off")))


def _read_off(path: Path) -> Mesh:
    # Minimal OFF reading for the embedded model only (no dependency on the io layer at import).
    from ..io import read_mesh

    return read_mesh(path)


def fandisk() -> Mesh:
    """The embedded fandisk mesh (CC0)."""
    return _read_off(fandisk_path())


def data_dir(required: bool = False) -> Path | None:
    """The shared data folder, or None when it cannot be found (``required=True`` raises)."""
    candidates = []
    env = os.environ.get("SPECTRAGEO_DATA")
    if env:
        candidates.append(Path(env))
    else:
        candidates.append(Path.cwd() / ".." / "shared" / "data")
        # source checkout: <repo>/src/spectrageo/datasets/__init__.py -> <repo>/../shared/data
        candidates.append(_HERE.parents[3].parent / "shared" / "data")
    for c in candidates:
        if c.is_dir():
            return c.resolve()
    if required:
        from .._errors import InvalidInputError

        where = env if env else " or ".join(str(c) for c in candidates)
        raise InvalidInputError(
            f"shared data folder not found at {where}; set SPECTRAGEO_DATA to its location."
        )
    return None


def denoise_pairs(root: Path | None = None) -> list[tuple[str, Path, Path]]:
    """``(name, noisy_path, original_path)`` for every pair in ``<data>/denoise/*/``, sorted by name."""
    root = Path(root) if root is not None else data_dir(required=True)
    base = root / "denoise" if (root / "denoise").is_dir() else root
    out = []
    for d in sorted(p for p in base.iterdir() if p.is_dir()):
        noisy = next(iter(sorted(d.glob("Noisy.*"))), None)
        orig = next(iter(sorted(d.glob("Original.*"))), None)
        if noisy is not None and orig is not None:
            out.append((d.name, noisy, orig))
    return out


__all__ = ["data_dir", "denoise_pairs", "fandisk", "fandisk_path"]
