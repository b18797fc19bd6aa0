"""``spectrageo saliency | features | curves | simplify | inspect`` (thesis Section 4.4 and 6.1).

Values go to ``.npy`` (array), ``.csv`` (one value per line) or ``.ply`` (the input geometry with the
values as a vertex or face property and jet colours quantised to 64 classes, as the thesis
visualises; per-face values are coloured through their first-ring mean at the vertices, since PLY
viewers colour vertices).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from ._argtypes import seed_type
from .batch_cmds import add_tile_options

_VALUE_SUFFIXES = (".npy", ".csv", ".ply")


def _status(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _suffix(path: str) -> str:
    p = Path(path)
    suf = p.suffix.lower()
    if suf == ".gz":
        suf = Path(p.stem).suffix.lower()
    if suf not in _VALUE_SUFFIXES:
        raise InvalidInputError(
            f"`--out` must end with one of {', '.join(_VALUE_SUFFIXES)}; got {path!r}."
        )
    return suf


def _read_mesh(path: str):
    from .. import io
    from ..geometry import Mesh

    obj = io.read(path)
    if not isinstance(obj, Mesh):
        raise InvalidInputError(f"{path!r} is not a triangle mesh ({type(obj).__name__}).")
    return obj


def _write_values(path: str, values: np.ndarray, *, geometry=None, per: str = "vertex", name: str):
    """Write values to .npy/.csv, or as a property + jet colours of ``geometry`` to .ply."""
    from .. import io
    from .._colormap import jet
    from ..geometry import Mesh, PointCloud
    from ..io import atomic_write

    suf = _suffix(path)
    values = np.asarray(values)
    if suf == ".npy":
        with atomic_write(path) as tmp, open(tmp, "wb") as fh:
            np.save(fh, values)
        return
    if suf == ".csv":
        fmt = "%d" if np.issubdtype(values.dtype, np.integer) else "%.9g"
        with atomic_write(path) as tmp:
            np.savetxt(tmp, values if values.ndim > 1 else values[:, None], fmt=fmt, delimiter=",")
        return
    if geometry is None:
        raise InvalidInputError("a .ply output needs geometry; use .npy or .csv.")
    vals = values.astype(np.float64)
    if isinstance(geometry, PointCloud):
        out = PointCloud(
            geometry.points,
            normals=geometry.normals,
            colors=jet(vals),
            attributes={**geometry.attributes, name: vals},
        )
    else:
        if per == "face":
            from ..saliency._common import face_to_vertex

            shown = face_to_vertex(vals, geometry.faces, geometry.n_vertices)
            out = Mesh(
                geometry.vertices,
                geometry.faces,
                vertex_colors=jet(shown),
                face_attributes={name: vals},
            )
        else:
            out = Mesh(
                geometry.vertices,
                geometry.faces,
                vertex_colors=jet(vals),
                vertex_attributes={name: vals},
            )
    io.write(path, out)


# --------------------------------------------------------------------------- saliency
def cmd_saliency(args) -> int:
    from .. import io, saliency
    from ..geometry import Mesh, MeshAnimation, PointCloud

    _suffix(args.out)
    if getattr(args, "tile", None) is not None:  # out-of-core point clouds on Dask (issue 21)
        from .batch_cmds import cmd_saliency_tiled

        return cmd_saliency_tiled(args)
    obj, rep = io.read_with_report(args.input, nan_points="drop")
    t0 = time.perf_counter()
    if isinstance(obj, Mesh):
        s = saliency.saliency(
            obj.vertices,
            obj.faces,
            method=args.method,
            per=args.per,
            k=args.k,
            fast=args.fast,
        )
        _write_values(args.out, s, geometry=obj, per=args.per, name="saliency")
    elif isinstance(obj, PointCloud):
        if args.per == "face":
            raise InvalidInputError("a point cloud has no faces; use --per vertex.")
        s = saliency.pointcloud_saliency(obj.points, k=args.k)
        if rep.source_index is not None and _suffix(args.out) != ".ply":
            # one value per input row, as the outlier masks: NaN where a row (an organized
            # scan's missing measurement) had no coordinates; a .ply holds the points kept
            full = np.full(rep.n_input_vertices, np.nan)
            full[rep.source_index] = s
            s = full
            _status(f"{rep.n_nonfinite_rows} rows without coordinates (NaN): saliency NaN")
        _write_values(args.out, s, geometry=obj, name="saliency")
    elif isinstance(obj, MeshAnimation):
        if args.per == "face":
            raise InvalidInputError("animations are mapped per vertex; use --per vertex.")
        if _suffix(args.out) == ".ply":
            raise InvalidInputError("an animation map is (frames, vertices): use .npy or .csv.")
        res = saliency.animation_saliency(obj.frames, obj.faces, method=args.method, k=args.k)
        s = res.values
        _write_values(args.out, s, name="saliency")
        _status(
            f"recomputed {100 * res.recomputed_fraction[1:].mean():.1f} % of the vertices per frame"
            if obj.n_frames > 1
            else "one frame"
        )
    else:
        raise InvalidInputError(
            f"`saliency` needs a mesh or a point cloud; got {type(obj).__name__}."
        )
    _status(f"wrote {args.out} ({s.shape[-1]} values, {time.perf_counter() - t0:.2f} s)")
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
    from ..saliency import simplify

    mesh = _read_mesh(args.input)
    t0 = time.perf_counter()
    res = simplify(
        mesh.vertices,
        mesh.faces,
        ratio=args.ratio,
        n_classes=args.classes,
        rng=args.seed,
        method=args.method,
        k=args.k,
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
    from ..saliency import inspect

    ref = _read_mesh(args.reference)
    scan = _read_mesh(args.scan)
    if _suffix(args.out) != ".ply":
        res = inspect(
            ref.vertices, ref.faces, scan.vertices, scan.faces, method=args.method, k=args.k
        )
        _write_values(args.out, res.deviation, name="deviation")
    else:
        res = inspect(
            ref.vertices, ref.faces, scan.vertices, scan.faces, method=args.method, k=args.k
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
    p.add_argument("--per", choices=["vertex", "face"], default="vertex")
    p.add_argument("--method", choices=["combined", "spectral", "geometric"], default="combined")
    p.add_argument("--k", type=int, default=25, help="faces per patch besides the face (25)")
    p.add_argument(
        "--fast", action="store_true", help="leave the least salient class out of the RPCA"
    )
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


__all__ = ["register"]
