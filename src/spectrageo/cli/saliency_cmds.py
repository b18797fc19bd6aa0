"""``spectrageo saliency | features | curves | simplify | inspect`` (thesis Section 4.4 and 6.1).

Values go to ``.npy``, ``.csv`` or ``.ply`` (see :mod:`spectrageo.distributed._values`).
"""

from __future__ import annotations

import time

import numpy as np

from .._errors import InvalidInputError
from ..distributed import COMMANDS
from ..distributed._values import value_suffix as _suffix
from ..distributed._values import write_values as _write_values
from ._argtypes import seed_type
from ._common import (
    add_schema_options,
    add_tile_options,
    apply_help,
    check_outputs,
    check_tile,
    status,
)

HELP = {
    "saliency": (
        "Saliency map of a mesh, point cloud or animation (Section 6.1), per vertex or face.",
        "spectrageo saliency part.obj --out saliency.ply --per vertex",
    ),
    "features": (
        "Corner / edge / flat classification of faces or vertices (Section 4.4, Eq. 4.14-4.15).",
        "spectrageo features part.obj --out classes.npy",
    ),
    "curves": (
        "Feature vertices and feature curves (Section 6.1.1).",
        "spectrageo curves part.obj --out curves.ply",
    ),
    "simplify": (
        "Saliency-aware simplification (Algorithm 15).",
        "spectrageo simplify model.off small.ply --ratio 0.8",
    ),
    "inspect": (
        "Saliency deviation of a scanned, scaled or aged copy against a reference (Eq. 6.17-6.19).",
        "spectrageo inspect reference.ply scan.ply --out heat.ply",
    ),
}


def _status(msg: str) -> None:
    status(msg, always=True)


def _read_mesh(path: str):
    from .. import io
    from ..geometry import Mesh

    obj = io.read(path)
    if not isinstance(obj, Mesh):
        raise InvalidInputError(f"{path!r} is not a triangle mesh ({type(obj).__name__}).")
    return obj


def cmd_saliency(args) -> int:
    """``spectrageo saliency IN --out OUT``: in memory, or tiled on Dask with ``--tile``."""
    if getattr(args, "tile", None) is None:
        return COMMANDS["saliency"].run(args)
    _suffix(args.out)
    return cmd_saliency_tiled(args)


def cmd_saliency_tiled(args) -> int:
    """``spectrageo saliency IN --out OUT --tile N``: :func:`spectrageo.distributed.saliency_tiled`."""
    from .. import _progress, distributed

    check_tile(args)
    if args.per == "face":
        raise InvalidInputError("a point cloud has no faces; use --per vertex.")
    check_outputs([args.input], [args.out])
    res = distributed.saliency_tiled(
        args.input,
        args.out,
        distributed.TileOptions(
            args.tile,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=_progress.progress_enabled(),
        ),
        k=args.k,
    )
    i = res.info
    status(
        f"wrote {args.out} ({res.n_points} values, {res.n_tiles} tiles of <= "
        f"{i['tile_points_max']} points, halo +{100 * i['halo_fraction_mean']:.0f} %, "
        f"{i['n_workers']} workers, {i['time_total_s']:.2f} s)"
    )
    return 0


# --------------------------------------------------------------------------- features
def cmd_features(args) -> int:
    from ..geometry.features import LABEL_NAMES, classify_faces, classify_vertices

    mesh = _read_mesh(args.input)
    _suffix(args.out)
    if args.per == "face":
        fc = classify_faces(mesh.vertices, mesh.faces, patch=args.patch)
    else:
        fc = classify_vertices(mesh.vertices, mesh.faces, patch=args.patch)
    labels = fc.labels.astype(np.int64)
    _write_values(args.out, labels, geometry=mesh, per=args.per, name="feature_class")
    counts = ", ".join(f"{k} {v}" for k, v in fc.counts.items())
    _status(f"wrote {args.out} ({'/'.join(LABEL_NAMES)} = 0/1/2; {counts})")
    return 0


# --------------------------------------------------------------------------- curves
def cmd_curves(args) -> int:
    from ..saliency import feature_curves

    mesh = _read_mesh(args.input)
    _suffix(args.out)
    res = feature_curves(
        mesh.vertices,
        mesh.faces,
        patch=args.patch,
        max_curves=args.max_curves,
        connected=args.connected,
    )
    _write_values(args.out, res.labels, geometry=mesh, name="curve")
    n_feat = int((res.labels >= 0).sum())
    _status(
        f"wrote {args.out}: {res.n_curves} curves over {n_feat} feature vertices "
        f"(-1 = not a feature)"
    )
    return 0


# --------------------------------------------------------------------------- simplify
def cmd_simplify(args) -> int:
    from .. import io
    from ..geometry import Mesh
    from ..saliency import SaliencyOptions, simplify

    mesh = _read_mesh(args.input)
    t0 = time.perf_counter()
    res = simplify(
        mesh.vertices,
        mesh.faces,
        ratio=args.ratio,
        n_classes=args.classes,
        rng=args.seed,
        method=args.method,
        options=SaliencyOptions(k=args.k),
    )
    io.write(args.output, Mesh(res.vertices, res.faces))
    frac = ", ".join(f"{p:.2f}" for p in res.keep_fractions)
    _status(
        f"wrote {args.output}: {len(res.vertices)} of {mesh.n_vertices} vertices, "
        f"{len(res.faces)} faces (kept per class: {frac}; {time.perf_counter() - t0:.2f} s)"
    )
    return 0


# --------------------------------------------------------------------------- inspect
def cmd_inspect(args) -> int:
    from .. import io
    from .._colormap import jet
    from ..geometry import Mesh
    from ..saliency import SaliencyOptions, inspect

    ref = _read_mesh(args.reference)
    scan = _read_mesh(args.scan)
    if _suffix(args.out) != ".ply":
        res = inspect(
            ref.vertices,
            ref.faces,
            scan.vertices,
            scan.faces,
            method=args.method,
            options=SaliencyOptions(k=args.k),
        )
        _write_values(args.out, res.deviation, name="deviation")
    else:
        res = inspect(
            ref.vertices,
            ref.faces,
            scan.vertices,
            scan.faces,
            method=args.method,
            options=SaliencyOptions(k=args.k),
        )
        out = Mesh(
            scan.vertices,
            scan.faces,
            vertex_colors=jet(res.heat, vmin=0.0),
            vertex_attributes={
                "deviation": res.deviation,
                "abs_deviation": res.heat,
                "distance": res.distance,
            },
        )
        io.write(args.out, out)
    _status(
        f"wrote {args.out}: mean |deviation| {res.heat.mean():.4g}, max {res.heat.max():.4g}, "
        f"95th percentile {np.percentile(res.heat, 95):.4g}"
    )
    return 0


# --------------------------------------------------------------------------- registration
def register(sub) -> None:
    """Add the saliency command group to the ``spectrageo`` sub-parsers."""
    p = sub.add_parser(
        "saliency", help="saliency map of a mesh, point cloud or animation (Sec. 6.1)"
    )
    p.add_argument("input")
    p.add_argument("--out", required=True, help="FILE.npy | FILE.csv | FILE.ply (jet colours)")
    add_schema_options(p, COMMANDS["saliency"])
    add_tile_options(p, "a point cloud")
    p.set_defaults(func=cmd_saliency)

    p = sub.add_parser("features", help="corner / edge / flat classification (Sec. 4.4)")
    p.add_argument("input")
    p.add_argument("--out", required=True, help="FILE.npy | FILE.csv | FILE.ply")
    p.add_argument("--patch", type=int, default=15, help="patch size (15)")
    p.add_argument("--per", choices=["face", "vertex"], default="face")
    p.set_defaults(func=cmd_features)

    p = sub.add_parser("curves", help="feature vertices and feature curves (Sec. 6.1.1)")
    p.add_argument("input")
    p.add_argument("--out", required=True, help="FILE.npy | FILE.csv | FILE.ply (curve ids)")
    p.add_argument("--patch", type=int, default=15, help="patch size of the saliency (15)")
    p.add_argument("--max-curves", type=int, default=5, dest="max_curves")
    p.add_argument("--connected", action="store_true", help="split curves into connected pieces")
    p.set_defaults(func=cmd_curves)

    p = sub.add_parser("simplify", help="saliency-aware simplification (Algorithm 15)")
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument(
        "--ratio", type=float, default=0.8, help="fraction of vertices removed (0.8 keeps 20 %%)"
    )
    p.add_argument("--classes", type=int, default=4, help="saliency classes (4)")
    p.add_argument("--method", choices=["combined", "spectral", "geometric"], default="combined")
    p.add_argument("--k", type=int, default=25)
    p.add_argument("--seed", type=seed_type, default=0)
    p.set_defaults(func=cmd_simplify)

    p = sub.add_parser(
        "inspect", help="saliency deviation of a scanned/scaled/aged copy (Eq. 6.17-6.19)"
    )
    p.add_argument("reference")
    p.add_argument("scan")
    p.add_argument("--out", required=True, help="heat.ply (or .npy/.csv of the deviation)")
    p.add_argument("--method", choices=["combined", "spectral", "geometric"], default="combined")
    p.add_argument("--k", type=int, default=25)
    p.set_defaults(func=cmd_inspect)
    apply_help(sub, HELP)


__all__ = ["register"]
