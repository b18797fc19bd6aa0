"""``spectrageo info | convert | noise | metrics``: file summaries, format conversion, synthetic
noise and comparison with a reference."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..distributed import COMMANDS, describe
from ._argtypes import seed_type
from ._common import add_schema_options, apply_help, check_outputs, err, fmt, print_json, status
from ._common import read_reported as _read

HELP = {
    "info": (
        "Summary of a geometry file: kind, counts, bounding box, mean edge length, what reading\n"
        "repaired (welded soup vertices, rows without coordinates) and, for meshes, the topology\n"
        "(components, boundary loops, non-manifold edges/vertices, duplicate and unreferenced\n"
        "vertices, degenerate faces, genus).",
        "spectrageo info part.stl --json",
    ),
    "convert": (
        "Convert between formats, keeping vertex order, normals, colours, attributes and OBJ\n"
        "texture coordinates where the target format can hold them. STL and triangle soups are\n"
        "welded on read (--no-weld keeps the soup).",
        "spectrageo convert scan.ply scan.obj",
    ),
    "noise": (
        "Add seeded synthetic noise with ground truth: Gaussian along normals (Eq. 4.36), uniform,\n"
        "impulsive; point clouds also outliers-far | outliers-near.",
        "spectrageo noise fandisk.off noisy.ply --kind gaussian --level 0.3 --seed 0",
    ),
    "metrics": (
        "Compare a result with a reference: per-vertex metrics (theta, distances, NMSVE) where\n"
        "vertices correspond, symmetric surface distances (Hausdorff, Chamfer, F-score) always.",
        "spectrageo metrics denoised.ply original.ply --json",
    ),
}


def cmd_info(args) -> int:
    from ..io._common import split_suffix

    if split_suffix(Path(args.file))[0] in (".sgc", ".sga"):  # compressed file: header summary
        from .compress_cmds import cmd_info_sgc

        return cmd_info_sgc(args)
    from .. import io
    from ..geometry import Mesh, MeshAnimation

    obj, rep = io.read_with_report(
        args.file, kind=args.kind, weld=False if args.no_weld else None, nan_points="drop"
    )
    d = {"file": str(args.file), **describe(obj)}
    d["n_input_rows"] = rep.n_input_vertices
    d["merged_vertices"] = rep.n_merged_vertices
    d["dropped_faces"] = rep.n_dropped_faces
    d["nonfinite_rows"] = rep.n_nonfinite_rows
    if isinstance(obj, Mesh | MeshAnimation):
        from ..geometry.topology import mesh_topology

        V = obj.vertices if isinstance(obj, Mesh) else obj.frames[0]
        d["topology"] = mesh_topology(V, obj.faces)
    if args.json:
        print_json(d)
    else:
        for k, v in d.items():
            if isinstance(v, list) and k == "n_points_per_frame" and len(v) > 8:
                v = f"{v[:4]} ... ({len(v)} frames)"
            if isinstance(v, dict):
                for k2, v2 in v.items():
                    if k2 not in d:  # counts already printed above
                        print(f"{k2:>24}: {fmt(v2)}")
                continue
            print(f"{k:>24}: {fmt(v) if not isinstance(v, str) else v}")
    return 0


def cmd_noise(args) -> int:
    from .. import io, noise
    from ..geometry import Mesh, MeshAnimation, PointCloud

    check_outputs([args.input], [args.output])
    outliers = args.kind.startswith("outliers")
    if outliers and args.level is not None:
        raise err(
            f"--level does not apply to --kind {args.kind}: the outliers' count is --fraction "
            "(of the points, default 0.1) and their placement is fixed by the kind."
        )
    level = 0.3 if args.level is None else args.level
    obj, _rep = _read(args.input)
    opts = {"kind": args.kind, "level": level, "rng": args.seed}
    if args.fraction is not None:
        opts["fraction"] = args.fraction
    if isinstance(obj, Mesh):
        out = obj.with_vertices(noise.apply(obj.vertices, obj.faces, **opts))
    elif isinstance(obj, MeshAnimation):
        out = obj.with_frames(noise.animation_noise(obj.frames, obj.faces, **opts))
    elif isinstance(obj, PointCloud):
        if outliers:
            kind = args.kind.split("-", 1)[1] if "-" in args.kind else "far"
            fraction = 0.1 if args.fraction is None else args.fraction
            P, labels = noise.add_outliers(obj.points, fraction=fraction, kind=kind, rng=args.seed)
            out = PointCloud(P, attributes={"outlier": labels.astype(np.uint8)})
        else:
            out = PointCloud(noise.apply(obj.points, None, **opts))
    else:
        raise err(
            f"`noise` supports meshes, animations and point clouds; got {type(obj).__name__}."
        )
    io.write(args.output, out)
    what = f"fraction {fraction}" if outliers and isinstance(obj, PointCloud) else f"level {level}"
    status(f"wrote {args.output} ({args.kind} noise, {what}, seed {args.seed})")
    return 0


# --------------------------------------------------------------------------- metrics
def _read_measured(path):
    """The file as read by the other commands, or unwelded where welding would refuse it (every
    face collapsed): a metric measures a wrecked result instead of refusing it."""
    from .._errors import InvalidInputError

    try:
        return _read(path)[0]
    except InvalidInputError as exc:
        try:
            return _read(path, weld=False)[0]
        except InvalidInputError:
            raise exc from None


def cmd_metrics(args) -> int:
    from .. import metrics
    from .._validation import check_positive
    from ..geometry import Mesh, MeshAnimation, PointCloud

    radius = getattr(args, "radius", None)
    if radius is not None:
        check_positive(radius, "radius")
    res, ref = _read_measured(args.result), _read_measured(args.reference)
    if isinstance(res, MeshAnimation) and isinstance(ref, MeshAnimation):
        if radius is not None:
            raise err("`radius` applies to meshes and point clouds, not to animations.")
        d = metrics.compare_animation(res.frames, ref.frames, ref.faces, faces_result=res.faces)
    elif isinstance(res, Mesh | PointCloud) and isinstance(ref, Mesh | PointCloud):
        # per-vertex metrics need vertex correspondence: two meshes, same count, identical faces
        why = None
        if not (isinstance(res, Mesh) and isinstance(ref, Mesh)):
            why = "a point cloud has no vertex correspondence"
        elif res.n_vertices != ref.n_vertices:
            why = f"{res.n_vertices} and {ref.n_vertices} vertices"
        elif not np.array_equal(res.faces, ref.faces):
            why = "different faces"
        d = {}
        if why is None:
            d = metrics.compare(res, ref, hausdorff_distance=False)
        else:
            status(f"no vertex correspondence ({why}): surface metrics only")
        d.update(metrics.compare_surfaces(res, ref, radius=radius))
        d["correspondence"] = why is None
        if why is not None:
            d["correspondence_reason"] = why
    else:
        raise err(
            "`metrics` compares two meshes, two point clouds, a mesh and a point cloud, or two "
            f"animations; got {type(res).__name__} and {type(ref).__name__}."
        )
    if args.json:
        print_json(d)
    else:
        for k, v in d.items():
            if isinstance(v, list | np.ndarray) and len(v) > 8:
                v = f"{fmt(list(v[:4]))} ... ({len(v)} values)"
            print(f"{k:>22}: {fmt(v) if not isinstance(v, str) else v}")
    return 0


def register(sub) -> None:
    """Add ``info``, ``convert``, ``noise`` and ``metrics``."""
    p = sub.add_parser("info", help="summary of a geometry file (counts, bbox, mean edge length)")
    p.add_argument("file")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument(
        "--kind",
        choices=["mesh", "points", "animation", "sequence"],
        default=None,
        help="force how the file is interpreted",
    )
    p.add_argument(
        "--no-weld",
        action="store_true",
        help="keep the corners of STL/soup triangles apart (default: welded)",
    )
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("convert", help="convert between formats (vertex order preserved)")
    p.add_argument("input")
    p.add_argument("output")
    add_schema_options(p, COMMANDS["convert"])
    p.set_defaults(func=COMMANDS["convert"].run)

    p = sub.add_parser("noise", help="add seeded synthetic noise (Gaussian along normals, ...)")
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument(
        "--kind",
        default="gaussian",
        help="meshes and point clouds: gaussian, uniform, impulsive, quantization; animations "
        "also spatial-mask; point clouds also outliers-far, outliers-near",
    )
    p.add_argument(
        "--level",
        type=float,
        default=None,
        help="noise level relative to the mean edge length (Eq. 4.36; default 0.3; not for the "
        "outlier kinds, whose count is --fraction)",
    )
    p.add_argument(
        "--fraction",
        type=float,
        default=None,
        help="fraction of vertices (impulsive) or outliers per point (outliers-*, default 0.1)",
    )
    p.add_argument("--seed", type=seed_type, default=0)
    p.set_defaults(func=cmd_noise)

    p = sub.add_parser(
        "metrics",
        help="compare a result with a reference (theta, distances, NMSVE, Hausdorff, Chamfer, "
        "F-score)",
    )
    p.add_argument("result", help="mesh, point cloud or animation")
    p.add_argument(
        "reference",
        help="mesh or point cloud (any resolution: without vertex correspondence only the "
        "surface metrics are reported), or an animation for an animation",
    )
    p.add_argument("--json", action="store_true")
    p.add_argument(
        "--radius",
        type=float,
        default=None,
        metavar="R",
        help="F-score distance threshold in model units (default: 1%% of the reference's "
        "bounding-box diagonal)",
    )
    p.set_defaults(func=cmd_metrics)
    apply_help(sub, HELP)
