"""File handling shared by the single-file commands: reading with a repair report, output checks,
status lines on stderr and atomic ``.npy`` writes."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError

#: Set by the command line's ``--quiet``: no status lines on stderr.
QUIET = False


def status(msg: str, *, always: bool = False) -> None:
    """One status line on stderr, unless :data:`QUIET` (``always``: regardless)."""
    if always or not QUIET:
        print(msg, file=sys.stderr, flush=True)


def read_reported(path, *, kind=None, weld=None, nan_points="drop", no_weld_option=False):
    """Read through :func:`spectrageo.io.read_with_report` and say on stderr what was repaired
    (``no_weld_option``: the command has ``--no-weld``, which the message then mentions). The
    policy of every command: point-cloud rows with NaN/inf coordinates are dropped and counted
    on stderr; mesh vertices cannot be dropped and refuse."""
    from .. import io

    obj, rep = io.read_with_report(path, kind=kind, weld=weld, nan_points=nan_points)
    name = Path(path).name
    if rep.n_merged_vertices:
        extra = f", {rep.n_dropped_faces} collapsed faces dropped" if rep.n_dropped_faces else ""
        keep = "; --no-weld keeps them apart" if no_weld_option else ""
        status(
            f"{name}: welded {rep.n_input_vertices} vertices into "
            f"{rep.n_input_vertices - rep.n_merged_vertices} (triangle soup{keep}){extra}"
        )
    if rep.n_nonfinite_rows:
        status(
            f"{name}: {rep.n_nonfinite_rows} of {rep.n_input_vertices} rows have NaN/inf "
            "coordinates (no measurement) and are left out"
        )
    return obj, rep


def _same_file(a, b) -> bool:
    pa, pb = Path(a), Path(b)
    try:
        return pa.exists() and pb.exists() and pa.samefile(pb)
    except OSError:
        return False


def check_outputs(inputs, outputs) -> None:
    """Refuse to write an output over an input file, or into a folder that does not exist;
    checked before any work, so that a command that cannot write all of its outputs writes none."""
    for out in outputs:
        if out is None:
            continue
        for inp in inputs:
            if _same_file(inp, out):
                raise InvalidInputError(
                    f"output {out} is the input file {inp}; write to another path "
                    "(the input would be overwritten)."
                )
        parent = Path(out).parent
        if not (parent if str(parent) else Path(".")).is_dir():
            raise InvalidInputError(f"output folder does not exist: {parent} (for {out})")


def save_npy(path, arr) -> None:
    """Write ``arr`` to ``path`` atomically (object arrays pickled)."""
    from ..io import atomic_write

    with atomic_write(path) as tmp, open(tmp, "wb") as fh:
        np.save(fh, arr, allow_pickle=arr.dtype == object)
