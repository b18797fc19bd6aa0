"""Helpers shared by the ``spectrageo`` sub-commands: messages, JSON output, options from a
command schema, help texts and the out-of-core options."""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from .._errors import InvalidInputError
from ..distributed import _files, json_default
from ..distributed._files import check_outputs, read_reported, save_npy, status

__all__ = [
    "add_schema_options",
    "add_tile_options",
    "apply_help",
    "check_outputs",
    "check_tile",
    "err",
    "fmt",
    "is_quiet",
    "print_json",
    "read_reported",
    "save_npy",
    "set_quiet",
    "status",
]


def err(msg: str) -> InvalidInputError:
    return InvalidInputError(msg)


def set_quiet(flag: bool) -> None:
    """``--quiet``: no status lines on stderr."""
    _files.QUIET = bool(flag)


def is_quiet() -> bool:
    return _files.QUIET


def print_json(obj) -> None:
    print(json.dumps(obj, indent=2, sort_keys=False, default=json_default))


def fmt(v) -> str:
    if isinstance(v, float | np.floating):
        return f"{v:.6g}"
    if isinstance(v, list | tuple | np.ndarray):
        return "[" + ", ".join(fmt(x) for x in v) + "]"
    return str(v)


def add_schema_options(p, schema, *, per_file: bool = True) -> None:
    """Add the options of a :class:`~spectrageo.distributed.CommandSchema` to parser ``p``
    (``per_file=False``: leave out those that name one file per run).

    A parser with a true ``summary`` attribute (the one ``spectrageo --help`` builds, which shows
    no option) gets the options without the help texts and choices that functions compute: those
    import the packages whose methods they list.
    """
    summary = getattr(p, "summary", False)
    groups: dict[str, object] = {}
    for o in schema.options:
        if o.per_file and not per_file:
            continue
        target = p
        if o.group is not None:
            if o.group not in groups:
                groups[o.group] = p.add_mutually_exclusive_group()
            target = groups[o.group]
        if summary and (callable(o.help) or callable(o.choices)):
            o = dataclasses.replace(o, help=None, choices=None)
        target.add_argument(*o.flags, **o.argparse_kwargs())


def add_tile_options(p, what: str = "the cloud") -> None:
    """``--tile N``, ``--scheduler ADDRESS``, ``--workers W``: out-of-core runs on Dask."""
    p.add_argument(
        "--tile",
        type=int,
        default=None,
        metavar="N",
        help=f"out of core: stream {what}, process tiles of about N points with halos on Dask "
        "(needs spectrageo[dist]; see docs/scaling.md)",
    )
    p.add_argument(
        "--scheduler", default=None, metavar="ADDRESS", help="with --tile: Dask scheduler"
    )
    p.add_argument("--workers", type=int, default=None, help="with --tile: local Dask workers")


def check_tile(args) -> None:
    if args.tile is None or args.tile <= 0:
        raise InvalidInputError(f"`tile` must be a positive number of points; got {args.tile}.")


def apply_help(sub, texts: dict[str, tuple[str, str]]) -> None:
    """Set the description and example of each ``command -> (description, example)``."""
    for name, (desc, example) in texts.items():
        sp = sub.choices[name]
        sp.description = desc
        sp.epilog = "example:\n  " + "\n  ".join(example.strip().splitlines())
