"""Sub-commands of ``spectrageo``. Each one parses options, calls the public API, prints results."""

from __future__ import annotations

import importlib
import json
import sys
import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError


def _err(msg: str) -> InvalidInputError:
    return InvalidInputError(msg)


def _print_json(obj) -> None:
    print(json.dumps(obj, indent=2, sort_keys=False, default=_json_default))


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _fmt(v) -> str:
    if isinstance(v, float | np.floating):
        return f"{v:.6g}"
    if isinstance(v, list | tuple | np.ndarray):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)


def _status(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- info
def describe(obj) -> dict:
    """Summary used by ``spectrageo info``: kind, counts, bbox and mean edge length."""
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
    raise _err(f"cannot describe object of type {type(obj).__name__}")


def cmd_info(args) -> int:
    from .. import io

    obj = io.read(args.file, kind=args.kind)
    d = {"file": str(args.file), **describe(obj)}
    if args.json:
        _print_json(d)
    else:
        for k, v in d.items():
            if isinstance(v, list) and k == "n_points_per_frame" and len(v) > 8:
                v = f"{v[:4]} ... ({len(v)} frames)"
            print(f"{k:>18}: {_fmt(v) if not isinstance(v, str) else v}")
    return 0


# --------------------------------------------------------------------------- convert
def cmd_convert(args) -> int:
    from .. import io

    obj = io.read(args.input, kind=args.kind, weld=args.weld)
    kw = {}
    if args.ascii:
        kw["binary"] = False
    io.write(args.output, obj, **kw)
    _status(f"wrote {args.output} ({describe(obj)['kind']})")
    return 0


# --------------------------------------------------------------------------- noise
def cmd_noise(args) -> int:
    from .. import io, noise
    from ..geometry import Mesh, MeshAnimation, PointCloud

    obj = io.read(args.input)
    opts = {"kind": args.kind, "level": args.level, "rng": args.seed}
    if args.fraction is not None:
        opts["fraction"] = args.fraction
    if isinstance(obj, Mesh):
        out = obj.with_vertices(noise.apply(obj.vertices, obj.faces, **opts))
    elif isinstance(obj, MeshAnimation):
        out = obj.with_frames(noise.animation_noise(obj.frames, obj.faces, **opts))
    elif isinstance(obj, PointCloud):
        if args.kind.startswith("outliers"):
            kind = args.kind.split("-", 1)[1] if "-" in args.kind else "far"
            P, labels = noise.add_outliers(
                obj.points, fraction=args.fraction or 0.1, kind=kind, rng=args.seed
            )
            out = PointCloud(P, attributes={"outlier": labels.astype(np.uint8)})
        else:
            out = PointCloud(noise.apply(obj.points, None, **opts))
    else:
        raise _err(
            f"`noise` supports meshes, animations and point clouds; got {type(obj).__name__}."
        )
    io.write(args.output, out)
    _status(f"wrote {args.output} ({args.kind} noise, level {args.level}, seed {args.seed})")
    return 0


# --------------------------------------------------------------------------- metrics
def cmd_metrics(args) -> int:
    from .. import io, metrics
    from ..geometry import Mesh, MeshAnimation

    res = io.read(args.result)
    ref = io.read(args.reference)
    if isinstance(res, MeshAnimation) and isinstance(ref, MeshAnimation):
        d = metrics.compare_animation(res.frames, ref.frames, ref.faces, faces_result=res.faces)
    elif isinstance(res, Mesh) and isinstance(ref, Mesh):
        d = metrics.compare(res.vertices, ref.vertices, ref.faces, faces_result=res.faces)
    else:
        raise _err(
            f"`metrics` compares two meshes or two animations; got {type(res).__name__} and {type(ref).__name__}."
        )
    if args.json:
        _print_json(d)
    else:
        for k, v in d.items():
            if isinstance(v, list | np.ndarray) and len(v) > 8:
                v = f"{_fmt(list(v[:4]))} ... ({len(v)} values)"
            print(f"{k:>20}: {_fmt(v) if not isinstance(v, str) else v}")
    return 0


# --------------------------------------------------------------------------- denoise
def cmd_denoise(args) -> int:
    from .. import denoise, io
    from .._progress import progress
    from ..geometry import Mesh, MeshAnimation

    obj = io.read(args.input)
    opts = {}
    if args.preset:
        opts["preset"] = args.preset
    if args.pre:
        opts["pre"] = args.pre
    t0 = time.perf_counter()
    if isinstance(obj, Mesh):
        out = obj.with_vertices(
            denoise.denoise(obj.vertices, obj.faces, method=args.method, **opts)
        )
    elif isinstance(obj, MeshAnimation):
        dyn = getattr(denoise, "dynamic_methods", lambda: [])()
        if args.method in dyn:
            frames = denoise.denoise_animation(obj.frames, obj.faces, method=args.method, **opts)
        else:
            denoise.get(args.method)  # validate the name before the loop
            frames = np.stack(
                [
                    denoise.denoise(f, obj.faces, method=args.method, **opts)
                    for f in progress(
                        obj.frames, desc=f"{args.method} per frame", total=obj.n_frames
                    )
                ]
            )
        out = obj.with_frames(frames)
    else:
        raise _err(f"`denoise` needs a mesh or a mesh animation; got {type(obj).__name__}.")
    io.write(args.output, out)
    _status(f"wrote {args.output} ({args.method}, {time.perf_counter() - t0:.2f} s)")
    return 0


# --------------------------------------------------------------------------- outliers
def cmd_outliers(args) -> int:
    from .. import io, outliers
    from ..geometry import PointCloud, PointCloudSequence

    obj = io.read(args.input, kind=None)
    opts = {"method": args.method, "k": args.k}
    if args.threshold is not None:
        opts["threshold"] = args.threshold
    if isinstance(obj, PointCloudSequence):
        if args.method != "rpca":
            raise _err("sequences are cleaned with --method rpca (Section 5.4.3).")
        res = outliers.clean_sequence(
            obj, k=args.k, **({"tau": args.threshold} if args.threshold else {})
        )
        io.write(args.output, res.frames)
        keep = np.array(res.keep, dtype=object) if not _same_len(res.keep) else np.stack(res.keep)
        if args.mask:
            _save_npy(args.mask, keep)
        _status(f"wrote {args.output} ({obj.n_frames} frames)")
        return 0
    if not isinstance(obj, PointCloud):
        obj = io.read(args.input, kind="points")
    res = outliers.remove_outliers(obj, **opts)
    io.write(
        args.output, res.points if isinstance(res.points, PointCloud) else obj.select(res.keep)
    )
    if args.mask:
        _save_npy(args.mask, np.asarray(res.keep, dtype=bool))
    if args.scores:
        _save_npy(args.scores, np.asarray(res.scores, dtype=np.float64))
    n = len(res.keep)
    _status(f"wrote {args.output}: kept {int(np.sum(res.keep))} of {n} points ({args.method})")
    return 0


def _same_len(arrs) -> bool:
    return len({len(a) for a in arrs}) <= 1


def _save_npy(path, arr) -> None:
    from ..io import atomic_write

    with atomic_write(path) as tmp, open(tmp, "wb") as fh:
        np.save(fh, arr, allow_pickle=arr.dtype == object)


# --------------------------------------------------------------------------- evaluate
def cmd_evaluate(args) -> int:
    from ..datasets import data_dir

    data = Path(args.data) if args.data else data_dir(required=True)
    if not data.is_dir():
        raise _err(f"`--data` must be a folder; got {data}.")
    methods = args.methods.split(",") if args.methods else None
    if args.what == "denoise":
        from ..evaluate import denoise as ev

        rows = ev.evaluate_denoise(data, methods=methods, out=args.out)
    elif args.what == "outliers":
        from ..evaluate import outliers as ev

        rows = ev.evaluate_outliers(
            data, **({"methods": tuple(methods)} if methods else {}), out=args.out
        )
    else:
        import importlib

        try:
            ev = importlib.import_module(f"spectrageo.evaluate.{args.what.replace('-', '_')}")
        except ModuleNotFoundError as exc:
            raise _err(f"no evaluation named {args.what!r}.") from exc
        rows = ev.evaluate(data, methods=methods, out=args.out)
    print(ev.format_markdown(rows))
    return 0


# --------------------------------------------------------------------------- demo
def cmd_demo(args) -> int:
    from .demo import run_demo

    run_demo(
        out_dir=Path(args.out),
        level=args.level,
        seed=args.seed,
        methods=args.methods.split(",") if args.methods else None,
    )
    return 0


# --------------------------------------------------------------------------- registration
def register_all(sub) -> None:
    p = sub.add_parser("info", help="summary of a geometry file (counts, bbox, mean edge length)")
    p.add_argument("file")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument(
        "--kind",
        choices=["mesh", "points", "animation", "sequence"],
        default=None,
        help="force how the file is interpreted",
    )
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("convert", help="convert between formats (vertex order preserved)")
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument("--kind", choices=["mesh", "points", "animation", "sequence"], default=None)
    p.add_argument(
        "--weld", action="store_true", help="merge coincident STL corners into shared vertices"
    )
    p.add_argument(
        "--ascii", action="store_true", help="write text variants (PLY, PCD) instead of binary"
    )
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser("noise", help="add seeded synthetic noise (Gaussian along normals, ...)")
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument(
        "--kind",
        default="gaussian",
        help="gaussian | uniform | impulsive | ... ; point clouds also outliers-far | outliers-near",
    )
    p.add_argument(
        "--level",
        type=float,
        default=0.3,
        help="noise level relative to the mean edge length (Eq. 4.36)",
    )
    p.add_argument(
        "--fraction", type=float, default=None, help="fraction of vertices (impulsive, outliers)"
    )
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=cmd_noise)

    p = sub.add_parser(
        "metrics", help="compare a result with a reference (theta, distances, NMSVE, Hausdorff)"
    )
    p.add_argument("result")
    p.add_argument("reference")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_metrics)

    p = sub.add_parser("denoise", help="denoise a mesh or a mesh animation")
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument(
        "--method", default="tsgsp", help="tsgsp | gnf | bnf | bilateral | taubin | laplacian | ..."
    )
    p.add_argument("--preset", default=None, help="method preset, e.g. scan | cad for tsgsp")
    p.add_argument(
        "--pre", default=None, choices=["coarse"], help="run the TSGSP coarse step first"
    )
    p.set_defaults(func=cmd_denoise)

    p = sub.add_parser(
        "outliers", help="remove outliers from a point cloud or a point-cloud sequence"
    )
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument("--method", default="rpca", choices=["rpca", "sor", "radius"])
    p.add_argument("--k", type=int, default=10, help="neighbours per point")
    p.add_argument(
        "--threshold", type=float, default=None, help="score threshold (default: automatic)"
    )
    p.add_argument(
        "--mask",
        default=None,
        help="write the boolean keep mask (input order, True = kept) to .npy",
    )
    p.add_argument("--scores", default=None, help="write per-point outlier scores to .npy")
    p.set_defaults(func=cmd_outliers)

    p = sub.add_parser("evaluate", help="run methods on the shared benchmark data and print tables")
    p.add_argument("what", help="denoise | outliers | denoise-dynamic | saliency")
    p.add_argument(
        "--data", default=None, help="data folder (default: $SPECTRAGEO_DATA or ../shared/data)"
    )
    p.add_argument("--methods", default=None, help="comma-separated method names")
    p.add_argument("--out", default=None, help="write FILE.md and FILE.csv")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("demo", help="noise + every denoiser on the embedded fandisk, with metrics")
    p.add_argument(
        "--out", default="spectrageo-demo", help="output folder (default ./spectrageo-demo)"
    )
    p.add_argument("--level", type=float, default=0.3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--methods", default=None, help="comma-separated subset of denoisers")
    p.set_defaults(func=cmd_demo)

    for name in _COMMAND_MODULES:
        try:
            mod = importlib.import_module(f"spectrageo.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"spectrageo.cli.{name}":
                raise
            continue
        mod.register(sub)


# Further command groups live in their own modules, each exposing ``register(sub)``:
# saliency/features/curves/simplify/inspect, the viewer.
_COMMAND_MODULES = ("saliency_cmds", "view_cmd")
