"""Sphinx configuration of the API reference (``bash docs/build.sh``).

The reference is built from the docstrings of the public API: the names each package exports in
its ``__init__`` (``__all__``). One page per package is generated at build time into
``_generated/`` (a summary table of every exported name, then each one documented), so the
reference follows ``__all__`` without hand edits. Docstrings are numpy-style, rendered by
numpydoc; the build treats every warning as an error.
"""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path

import spectrageo

project = "spectrageo"
author = "spectrageo contributors"
copyright = "spectrageo contributors, MIT licence"
release = spectrageo.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
]

root_doc = "index"
exclude_patterns = ["_build"]
templates_path: list[str] = []

# autodoc: members in the order written below (each package's ``__all__``); signatures keep the
# type hints, the numpy-style Parameters sections describe them.
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_class_signature = "mixed"
autodoc_preserve_defaults = True
autosummary_generate = False

# numpydoc: no automatic member tables for classes (autodoc lists the members already).
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_attributes_as_param_list = False
# Structural checks, errors under -W: unknown or misordered sections (GL06, GL07), a missing
# docstring or summary (GL08, SS01), documented parameters that do not exist or are out of order
# (PR02, PR03), a Returns section that does not start with its type (RT02).
numpydoc_validation_checks = {"GL06", "GL07", "GL08", "SS01", "PR02", "PR03", "RT02"}
# Constants are documented by ``#:`` comments, which numpydoc does not read.
numpydoc_validation_exclude = {r"\.[A-Z][A-Z0-9_]*$"}

html_theme = "alabaster"
html_title = f"spectrageo {release} API reference"
html_static_path: list[str] = []

# (package, page title); the order of the index.
PACKAGES = [
    ("spectrageo", "errors, warnings and the data model"),
    ("spectrageo.io", "reading and writing files"),
    ("spectrageo.geometry", "meshes, point clouds, animations"),
    ("spectrageo.graph", "graphs and Laplacians"),
    ("spectrageo.spectral", "graph Fourier transform and submeshes"),
    ("spectrageo.linalg", "low-rank and sparse solvers"),
    ("spectrageo.metrics", "quality metrics"),
    ("spectrageo.noise", "synthetic corruption with ground truth"),
    ("spectrageo.denoise", "denoising"),
    ("spectrageo.learn", "learned denoisers"),
    ("spectrageo.compress", "compression"),
    ("spectrageo.complete", "completion"),
    ("spectrageo.outliers", "outlier removal"),
    ("spectrageo.saliency", "saliency"),
    ("spectrageo.register", "registration and identification"),
    ("spectrageo.distributed", "batch and out-of-core processing on Dask"),
    ("spectrageo.viewer", "browser viewer"),
    ("spectrageo.datasets", "embedded and shared data"),
]

# Exported names left out of the reference, with the reason (none at present).
EXCLUDE: dict[str, str] = {}


def _home(obj: object) -> str | None:
    """The package page that documents ``obj`` (None: the package itself)."""
    mod = getattr(obj, "__module__", None) or ""
    for pkg, _ in PACKAGES[1:]:
        if mod == pkg or mod.startswith(pkg + "."):
            return pkg
    return None


def _page(pkg: str, title: str) -> str:
    module = importlib.import_module(pkg)
    names = [n for n in getattr(module, "__all__", []) if not n.startswith("__")]
    own, elsewhere = [], []
    for name in names:
        if f"{pkg}.{name}" in EXCLUDE:
            continue
        obj = getattr(module, name)
        home = _home(obj) if (inspect.isclass(obj) or inspect.isfunction(obj)) else None
        (elsewhere if home not in (None, pkg) else own).append((name, home))
    head = f"``{pkg}``: {title}"
    lines = [head, "=" * len(head), "", f".. automodule:: {pkg}", "   :no-members:", ""]
    lines += [f".. currentmodule:: {pkg}", ""]
    if own:
        lines += [".. autosummary::", "   :nosignatures:", ""]
        lines += [f"   {name}" for name, _ in own] + [""]
    if elsewhere:
        lines += ["Also exported here, documented with their own package:", ""]
        lines += [f"- :obj:`{pkg}.{name} <{home}.{name}>`" for name, home in elsewhere] + [""]
    left_out = [k for k in EXCLUDE if k.rsplit(".", 1)[0] == pkg]
    if left_out:
        lines += ["Not in this reference yet: " + ", ".join(f"``{k}``" for k in left_out), ""]
    for name, _ in own:
        obj = getattr(module, name)
        if inspect.isclass(obj):
            lines += [f".. autoclass:: {name}", "   :members:", ""]
        elif callable(obj):
            lines += [f".. autofunction:: {name}", ""]
        else:
            lines += [f".. autodata:: {name}", "   :annotation:", ""]
    return "\n".join(lines)


def _generate() -> None:
    out = Path(__file__).resolve().parent / "_generated"
    out.mkdir(exist_ok=True)
    for pkg, title in PACKAGES:
        path = out / f"{pkg}.rst"
        text = _page(pkg, title)
        if not path.exists() or path.read_text() != text:
            path.write_text(text)


_generate()
