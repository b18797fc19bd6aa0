"""Declarative description of a single-file command, and the JSON description of its results.

A :class:`CommandSchema` names a command, the function that runs it on one file, its options
(Python name, command-line flags, type, default, choices, help) and how its output is summarised
in a batch record. :func:`spectrageo.distributed.batch` builds each task's options from it; the
command line builds its argparse options from the same schema.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from .._errors import InvalidInputError

__all__ = ["CommandSchema", "Option", "describe", "json_default"]


@dataclass(frozen=True)
class Option:
    """One option of a command.

    Parameters
    ----------
    name : str
        Python name (the attribute of the command's namespace, ``no_weld``).
    flags : tuple of str
        Command-line spellings (``("--no-weld",)``).
    type : callable, optional
        Converter of a command-line string (``int``, ``float``); None keeps the string.
    default : object
        Value when the option is not given.
    choices : sequence or callable, optional
        Allowed values, or a function returning them (evaluated when a parser is built).
    help : str or callable, optional
        Help text, or a function returning it.
    switch : bool
        A flag without a value (``store_true``).
    metavar : str, optional
        Name of the value in the help.
    group : str, optional
        Options with the same group exclude each other.
    per_file : bool
        The option names one file per run, so a batch cannot take it.
    """

    name: str
    flags: tuple[str, ...]
    type: Callable[[str], Any] | None = None
    default: Any = None
    choices: Sequence[Any] | Callable[[], Sequence[Any]] | None = None
    help: str | Callable[[], str] | None = None
    switch: bool = False
    metavar: str | None = None
    group: str | None = None
    per_file: bool = False

    @property
    def initial(self) -> Any:
        """The value when the option is not given (``False`` for a switch without a default)."""
        return False if self.switch and self.default is None else self.default

    def argparse_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``ArgumentParser.add_argument`` for this option."""
        kw: dict[str, Any] = {"dest": self.name, "default": self.initial}
        if self.switch:
            kw["action"] = "store_true"
        elif self.type is not None:
            kw["type"] = self.type
        choices = self.choices() if callable(self.choices) else self.choices
        if choices is not None:
            kw["choices"] = list(choices)
        text = self.help() if callable(self.help) else self.help
        if text is not None:
            kw["help"] = text
        if self.metavar is not None:
            kw["metavar"] = self.metavar
        return kw


@dataclass(frozen=True)
class CommandSchema:
    """A single-file command: ``spectrageo NAME INPUT OUTPUT [options]``.

    Parameters
    ----------
    name : str
        Command name.
    run : callable
        ``run(namespace) -> int``: runs the command on ``namespace.input``, writing the output
        attribute; returns the exit status.
    output : {"output", "out"}
        Namespace attribute of the output path (``out`` is given as ``--out``).
    options : tuple of Option
        The command's options, in help order.
    result : callable
        ``result(output_path, keep_mask_path) -> dict``: the JSON description of one output.
    keep_mask : str, optional
        Option that a batch points at a hidden ``.npy`` file for ``result`` to read.
    """

    name: str
    run: Callable[[Any], int]
    output: str
    options: tuple[Option, ...]
    result: Callable[[Path, Path | None], dict] = field(repr=False)
    keep_mask: str | None = None

    @property
    def per_file(self) -> tuple[str, ...]:
        """Names of the options that name one file per run."""
        return tuple(o.name for o in self.options if o.per_file)

    def namespace(self, options: dict[str, Any]) -> SimpleNamespace:
        """Defaults of every option, then ``options`` (Python names) over them."""
        ns = SimpleNamespace(input=None, **{self.output: None})
        for o in self.options:
            setattr(ns, o.name, o.initial)
        allowed = sorted(o.name for o in self.options)
        for key, value in options.items():
            if key in self.per_file:
                raise InvalidInputError(
                    f"`{key}` names one file per run; {self.name} in a batch cannot take it."
                )
            if key not in allowed:
                raise InvalidInputError(
                    f"{self.name} has no option {key!r}; its options are {', '.join(allowed)}."
                )
            setattr(ns, key, value)
        return ns


def json_default(o):
    """``json.dumps`` fallback: arrays as lists, numpy scalars as numbers, paths as strings."""
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def describe(obj) -> dict:
    """Summary of a geometry object: kind, counts, bounding box and mean edge length."""
    from ..geometry import Mesh, MeshAnimation, PointCloud, PointCloudSequence, mean_edge_length

    if isinstance(obj, Mesh):
        lo, hi = obj.bbox()
        d = {
            "kind": "mesh",
            "n_vertices": obj.n_vertices,
            "n_faces": obj.n_faces,
            "n_frames": 1,
            "bbox": [lo.tolist(), hi.tolist()],
            "mean_edge_length": mean_edge_length(obj.vertices, obj.faces),
        }
        d["vertex_attributes"] = sorted(obj.vertex_attributes)
        d["face_attributes"] = sorted(obj.face_attributes)
        d["has_normals"] = obj.vertex_normals is not None
        d["has_colors"] = obj.vertex_colors is not None
        return d
    if isinstance(obj, PointCloud):
        lo, hi = obj.bbox()
        return {
            "kind": "point_cloud",
            "n_vertices": obj.n_points,
            "n_faces": 0,
            "n_frames": 1,
            "bbox": [lo.tolist(), hi.tolist()],
            "mean_edge_length": None,
            "has_normals": obj.normals is not None,
            "has_colors": obj.colors is not None,
            "attributes": sorted(obj.attributes),
        }
    if isinstance(obj, MeshAnimation):
        lo, hi = obj.bbox()
        return {
            "kind": "animation",
            "n_vertices": obj.n_vertices,
            "n_faces": obj.n_faces,
            "n_frames": obj.n_frames,
            "bbox": [lo.tolist(), hi.tolist()],
            "mean_edge_length": mean_edge_length(obj.frames[0], obj.faces),
        }
    if isinstance(obj, PointCloudSequence):
        lo, hi = obj.bbox()
        return {
            "kind": "point_sequence",
            "n_vertices": obj.n_points[0],
            "n_faces": 0,
            "n_frames": obj.n_frames,
            "bbox": [lo.tolist(), hi.tolist()],
            "mean_edge_length": None,
            "n_points_per_frame": obj.n_points,
        }
    raise InvalidInputError(f"cannot describe object of type {type(obj).__name__}")
