"""``spectrageo complete``: missing vertices of meshes, animations and point-cloud sequences, and
hole filling (thesis Section 5.3); runs :func:`spectrageo.distributed._run_codec.run_complete`.

- ``spectrageo complete IN OUT --known KNOWN.npy [--method mc|li|lsm]`` (meshes; the unknown rows
  of IN may hold anything, NaN included);
- ``spectrageo complete IN OUT --fill-holes [--method lsm|li|mc] [--max-hole N] [--density D]``
  (meshes with holes; ``lsm`` by default, see :func:`spectrageo.complete.fill_holes`);
- ``spectrageo complete IN.npz OUT.npz --known KNOWN.npy [--method motion|li|lia|mc|gmc]
  [--sweeps N]`` (animations with ``vertices`` + ``faces``; point-cloud sequences with ``points``
  (T, n, 3), where ``motion`` is Algorithm 13's WRLI).

``KNOWN.npy``: a boolean mask (n,) -- or (T, n) for animations -- or an integer index list.
"""

from __future__ import annotations

from ..distributed import COMMANDS
from ._common import add_schema_options


def register(sub) -> None:
    """Add ``complete`` to the ``spectrageo`` sub-parsers."""
    p = sub.add_parser(
        "complete", help="recover missing vertices or fill holes (meshes, animations; Sec. 5.3)"
    )
    p.add_argument("input", help="mesh file, or .npz animation / point-cloud sequence")
    p.add_argument("output")
    add_schema_options(p, COMMANDS["complete"])
    p.set_defaults(func=COMMANDS["complete"].run)
    p.description = (
        "Recover missing vertices of a mesh with known connectivity (rows of IN not marked in\n"
        "--known may hold anything, NaN included), close the holes of a mesh (--fill-holes), or\n"
        "recover missing vertices of an animation / point-cloud sequence frame by frame (online:\n"
        "frame t uses frames <= t). Known vertices are returned unchanged, vertex order is kept."
    )
    p.epilog = (
        "example:\n  spectrageo complete scan.ply filled.ply --known known.npy --method li\n"
        "  spectrageo complete part_with_holes.off closed.off --fill-holes\n"
        "  spectrageo complete crane.npz crane_full.npz --known known.npy --method motion"
    )
