"""Sub-commands of ``spectrageo``. Each one parses options, calls the public API, prints results."""

from __future__ import annotations

import importlib
import json
import sys
import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from ._argtypes import seed_type
from .batch_cmds import add_tile_options


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


#: Set by ``--quiet`` (see :mod:`.main`): no status lines on stderr.
QUIET = False


def _status(msg: str) -> None:
    if not QUIET:
        print(msg, file=sys.stderr, flush=True)


def _read(path, *, kind=None, weld=None, nan_points=None, no_weld_option=False):
    """Read through :func:`spectrageo.io.read_with_report` and say on stderr what was repaired
    (``no_weld_option``: the command has ``--no-weld``, which the message then mentions)."""
    from .. import io

    obj, rep = io.read_with_report(path, kind=kind, weld=weld, nan_points=nan_points)
    name = Path(path).name
    if rep.n_merged_vertices:
        extra = f", {rep.n_dropped_faces} collapsed faces dropped" if rep.n_dropped_faces else ""
        keep = "; --no-weld keeps them apart" if no_weld_option else ""
        _status(
            f"{name}: welded {rep.n_input_vertices} vertices into "
            f"{rep.n_input_vertices - rep.n_merged_vertices} (triangle soup{keep}){extra}"
        )
    if rep.n_nonfinite_rows:
        _status(
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


def _check_outputs(inputs, outputs) -> None:
    """Refuse to write an output over an input file (the input would be lost), or into a folder
    that does not exist: checked before any work, so that a command that cannot write all of its
    outputs writes none of them."""
    for out in outputs:
        if out is None:
            continue
        for inp in inputs:
            if _same_file(inp, out):
                raise _err(
                    f"output {out} is the input file {inp}; write to another path "
                    "(the input would be overwritten)."
                )
        parent = Path(out).parent
        if not (parent if str(parent) else Path(".")).is_dir():
            raise _err(f"output folder does not exist: {parent} (for {out})")


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
        _print_json(d)
    else:
        for k, v in d.items():
            if isinstance(v, list) and k == "n_points_per_frame" and len(v) > 8:
                v = f"{v[:4]} ... ({len(v)} frames)"
            if isinstance(v, dict):
                for k2, v2 in v.items():
                    if k2 not in d:  # counts already printed above
                        print(f"{k2:>24}: {_fmt(v2)}")
                continue
            print(f"{k:>24}: {_fmt(v) if not isinstance(v, str) else v}")
    return 0


# --------------------------------------------------------------------------- convert
def cmd_convert(args) -> int:
    from .. import io
    from ..geometry import Mesh
    from ..io._api import _MESH_WRITE, _POINTS_WRITE
    from ..io._common import split_suffix

    _check_outputs([args.input], [args.output])
    weld = True if args.weld else False if args.no_weld else None
    obj, _rep = _read(args.input, kind=args.kind, weld=weld, no_weld_option=True)
    suffix = split_suffix(Path(args.output))[0]
    if isinstance(obj, Mesh) and suffix in _POINTS_WRITE and suffix not in _MESH_WRITE:
        raise _err(
            f"{Path(args.output).name}: {suffix} holds points only, and {Path(args.input).name} "
            f"is a mesh with {obj.n_faces} faces; pass --kind points to write its vertices "
            "without the faces, or choose a mesh format (.ply, .obj, .off, .stl)."
        )
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

    _check_outputs([args.input], [args.output])
    outliers = args.kind.startswith("outliers")
    if outliers and args.level is not None:
        raise _err(
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
        raise _err(
            f"`noise` supports meshes, animations and point clouds; got {type(obj).__name__}."
        )
    io.write(args.output, out)
    what = f"fraction {fraction}" if outliers and isinstance(obj, PointCloud) else f"level {level}"
    _status(f"wrote {args.output} ({args.kind} noise, {what}, seed {args.seed})")
    return 0


# --------------------------------------------------------------------------- metrics
def cmd_metrics(args) -> int:
    from .. import metrics
    from .._validation import check_positive
    from ..geometry import Mesh, MeshAnimation, PointCloud

    radius = getattr(args, "radius", None)
    if radius is not None:
        check_positive(radius, "radius")
    res, _ = _read(args.result)
    ref, _ = _read(args.reference)
    if isinstance(res, MeshAnimation) and isinstance(ref, MeshAnimation):
        if radius is not None:
            raise _err("`radius` applies to meshes and point clouds, not to animations.")
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
            _status(f"no vertex correspondence ({why}): surface metrics only")
        d.update(metrics.compare_surfaces(res, ref, radius=radius))
        d["correspondence"] = why is None
        if why is not None:
            d["correspondence_reason"] = why
    else:
        raise _err(
            "`metrics` compares two meshes, two point clouds, a mesh and a point cloud, or two "
            f"animations; got {type(res).__name__} and {type(ref).__name__}."
        )
    if args.json:
        _print_json(d)
    else:
        for k, v in d.items():
            if isinstance(v, list | np.ndarray) and len(v) > 8:
                v = f"{_fmt(list(v[:4]))} ... ({len(v)} values)"
            print(f"{k:>22}: {_fmt(v) if not isinstance(v, str) else v}")
    return 0


# --------------------------------------------------------------------------- denoise
def cmd_denoise(args) -> int:
    from .. import denoise, io
    from .._progress import activity, progress
    from ..denoise._guard import is_folded
    from ..geometry import Mesh, MeshAnimation, PointCloud

    _check_outputs([args.input], [args.output])
    obj, _rep = _read(args.input, weld=False if args.no_weld else None, no_weld_option=True)
    opts = {}
    if args.preset:
        opts["preset"] = args.preset
    if args.pre:
        opts["pre"] = args.pre
    learned = ("bm3d-cnn", "dae")  # spectrageo.learn (issue 20)
    if args.weights is not None and args.method not in learned:
        raise _err(
            f"--weights applies to the learned methods {', '.join(learned)}; got {args.method!r}."
        )
    if args.weights is not None:
        opts["weights"] = args.weights
    if args.train_frames is not None and args.method != "dae":
        raise _err(f"--train-frames applies to --method dae only; got {args.method!r}.")
    motion = getattr(args, "motion", None)
    if motion is not None and args.train_frames is None:
        raise _err("--motion applies to --method dae with --train-frames only.")
    block_size = getattr(args, "block_size", None)
    if block_size is not None and args.method != "gft-rpca":
        raise _err(f"--block-size applies to --method gft-rpca only; got {args.method!r}.")
    t0 = time.perf_counter()
    if isinstance(obj, Mesh) and args.train_frames is not None:
        raise _err("--train-frames applies to animations (.npz or frame folders), not to a mesh.")
    if isinstance(obj, Mesh) and block_size is not None:
        raise _err("--block-size applies to animations (.npz or frame folders), not to a mesh.")
    if isinstance(obj, Mesh):
        with activity(f"denoise {args.method} ({obj.n_vertices} vertices)"):
            Vd = denoise.denoise(
                obj.vertices, obj.faces, method=args.method, weld=not args.no_weld, **opts
            )
        out = obj.with_vertices(Vd)
        if np.array_equal(Vd, obj.vertices):
            # the do-no-harm gate (spectrageo.denoise._guard) found no noise, or only detail
            from ..denoise._guard import coarse_shape, has_shared_edge

            if not has_shared_edge(obj.faces):
                _status(
                    "separate triangles (no edge shared by two faces), nothing to filter: the "
                    "vertices are written unchanged"
                )
            elif coarse_shape(obj.vertices, obj.faces).coarse:
                _status(
                    "coarse mesh (it turns by more per edge than noise would, coherently between "
                    "neighbours: Eqs. N11-N13 of spectrageo.denoise._guard), no noise found: the "
                    "vertices are written unchanged"
                )
            else:
                _status("no noise found: the vertices are written unchanged")
        elif args.method == "tsgsp" and is_folded(obj.vertices, obj.faces):
            # the gate's decision on the mesh as given (the reader has welded any soup)
            _status(
                "the noise has flipped triangles (folded mesh, Eq. N10 of "
                "spectrageo.denoise._guard): smoothed by lambda|mu blocks until the folds are "
                "gone, then by TSGSP's fine step only if they are"
            )
    elif isinstance(obj, MeshAnimation):
        dyn = getattr(denoise, "dynamic_methods", lambda: [])()
        if args.method == "dae" and args.train_frames is not None:
            opts["train_frames"] = args.train_frames
            if motion is not None:
                opts["motion"] = motion
        if block_size is not None:
            opts["block_size"] = block_size
        # `spectrageo batch` sets this inside a Dask task: the frame blocks then run as tasks of
        # the same cluster (spectrageo.distributed.gft_rpca_blocks, equal to the serial run)
        frame_blocks = getattr(args, "frame_blocks", None)
        if frame_blocks is not None and block_size is not None:
            with activity(f"denoise {args.method} ({obj.n_frames} frames, Dask frame blocks)"):
                frames = frame_blocks(obj.frames, obj.faces, **opts)
        elif args.method in dyn or args.method == "dae":
            with activity(f"denoise {args.method} ({obj.n_frames} frames)"):
                frames = denoise.denoise_animation(
                    obj.frames, obj.faces, method=args.method, **opts
                )
        else:
            denoise.get(args.method)  # validate the name before the loop
            frames = np.stack(
                [
                    denoise.denoise(f, obj.faces, method=args.method, weld=not args.no_weld, **opts)
                    for f in progress(
                        obj.frames, desc=f"{args.method} per frame", total=obj.n_frames
                    )
                ]
            )
        out = obj.with_frames(frames)
    else:
        what = "point cloud" if isinstance(obj, PointCloud) else "point-cloud sequence"
        raise _err(
            f"{Path(args.input).name} is a {what} (no faces); denoise needs a mesh or a mesh "
            "animation. For point clouds use `spectrageo outliers` (smoothing: --method rpca)."
        )
    io.write(args.output, out)
    _status(f"wrote {args.output} ({args.method}, {time.perf_counter() - t0:.2f} s)")
    return 0


# --------------------------------------------------------------------------- outliers
def cmd_outliers(args) -> int:
    from .. import io, outliers
    from ..geometry import Mesh, PointCloud, PointCloudSequence

    _check_outputs([args.input], [args.output, args.mask, args.scores])
    if getattr(args, "tile", None) is not None:  # out-of-core on Dask (issue 21)
        from .batch_cmds import cmd_outliers_tiled

        return cmd_outliers_tiled(args)
    obj, rep = _read(args.input, nan_points="drop")
    opts = {"method": args.method, "k": args.k, "device": getattr(args, "device", "cpu")}
    if args.threshold is not None:
        opts["threshold"] = args.threshold
    if isinstance(obj, PointCloudSequence):
        if args.method != "rpca":
            raise _err("sequences are cleaned with --method rpca (Section 5.4.3).")
        if args.scores:
            raise _err("--scores is written for single point clouds, not for sequences.")
        if getattr(args, "device", "cpu") == "cuda":
            raise _err("sequences are cleaned on the CPU; --device cuda applies to single clouds.")
        res = outliers.clean_sequence(
            obj, k=args.k, **({"tau": args.threshold} if args.threshold else {})
        )
        io.write(args.output, res.frames)
        keep = np.array(res.keep, dtype=object) if not _same_len(res.keep) else np.stack(res.keep)
        if args.mask:
            _save_npy(args.mask, keep)
        _status(f"wrote {args.output} ({obj.n_frames} frames)")
        return 0
    if isinstance(obj, Mesh):
        cloud = PointCloud(
            obj.vertices, obj.vertex_normals, obj.vertex_colors, obj.vertex_attributes
        )
    elif isinstance(obj, PointCloud):
        cloud = obj
    else:
        raise _err(
            f"{Path(args.input).name} is a mesh animation; outliers needs a point cloud, a mesh "
            "or a point-cloud sequence."
        )
    res = outliers.remove_outliers(cloud, **opts)
    keep = np.asarray(res.keep, dtype=bool)
    scores = np.asarray(res.scores, dtype=np.float64)
    extra = ""
    if isinstance(obj, Mesh):
        # keep the faces whose three corners are kept, re-indexed; say how many went
        kept_faces = keep[obj.faces].all(axis=1)
        new_index = np.cumsum(keep) - 1
        out = Mesh(
            obj.vertices[keep],
            new_index[obj.faces[kept_faces]],
            vertex_normals=None if obj.vertex_normals is None else obj.vertex_normals[keep],
            vertex_colors=None if obj.vertex_colors is None else obj.vertex_colors[keep],
            vertex_attributes={k: v[keep] for k, v in obj.vertex_attributes.items()},
            face_attributes={k: v[kept_faces] for k, v in obj.face_attributes.items()},
        )
        extra = f"; {int(kept_faces.sum())} of {obj.n_faces} faces kept (those of kept vertices)"
    else:
        out = res.points if isinstance(res.points, PointCloud) else obj.select(keep)
    if rep.source_index is not None:
        # masks and scores cover every input row: rows without coordinates are not kept, score inf
        n_in = rep.n_input_vertices
        full_keep = np.zeros(n_in, dtype=bool)
        full_keep[rep.source_index] = keep
        full_scores = np.full(n_in, np.inf)
        full_scores[rep.source_index] = scores
        keep, scores = full_keep, full_scores
        extra += f"; {rep.n_nonfinite_rows} rows without coordinates (NaN) not kept"
    io.write(args.output, out)
    if args.mask:
        _save_npy(args.mask, keep)
    if args.scores:
        _save_npy(args.scores, scores)
    if args.method == "rpca":
        i = res.info
        extra += (
            f"; threshold {res.threshold:.3g} spacings ({i.get('threshold_rule')}), "
            f"{i.get('n_cluster_outliers', 0)} in small outlier clusters, estimated "
            f"contamination {100 * i.get('contamination', 0.0):.1f} %"
        )
    # of the rows the mask covers: every input row, or the vertices a triangle soup welded into
    _status(
        f"wrote {args.output}: kept {int(np.sum(res.keep))} of {keep.shape[0]} points "
        f"({args.method}){extra}"
    )
    return 0


# --------------------------------------------------------------------------- robot
def cmd_robot(args) -> int:
    """``spectrageo robot IN OUT``: :func:`spectrageo.outliers.robot_pipeline` (Section 5.4.2)."""
    from .. import io, outliers
    from ..geometry import Mesh, PointCloud

    _check_outputs([args.input], [args.output, args.mask])
    if getattr(args, "tile", None) is not None:  # out-of-core on Dask (issue 21)
        from .batch_cmds import cmd_robot_tiled

        return cmd_robot_tiled(args)
    obj, _rep = _read(args.input)
    if isinstance(obj, Mesh):
        cloud = PointCloud(
            obj.vertices, obj.vertex_normals, obj.vertex_colors, obj.vertex_attributes
        )
    elif isinstance(obj, PointCloud):
        cloud = obj
    else:
        raise _err(f"{Path(args.input).name}: robot needs a point cloud or a mesh's vertices.")
    t0 = time.perf_counter()
    res = outliers.robot_pipeline(
        cloud,
        k=args.k,
        threshold=args.threshold,
        rpca_k=args.rpca_k,
        sigma1=args.sigma1,
        sigma2=args.sigma2,
        n_iter=args.n_iter,
        output="mesh" if args.mesh else "cloud",
    )
    io.write(args.output, res.mesh if args.mesh else res.points)
    if args.mask:
        _save_npy(args.mask, np.asarray(res.keep, dtype=bool))
    _status(
        f"wrote {args.output}: kept {int(np.sum(res.keep))} of {cloud.n_points} points, "
        f"filtered ({time.perf_counter() - t0:.2f} s)"
    )
    return 0


def _same_len(arrs) -> bool:
    return len({len(a) for a in arrs}) <= 1


def _save_npy(path, arr) -> None:
    from ..io import atomic_write

    with atomic_write(path) as tmp, open(tmp, "wb") as fh:
        np.save(fh, arr, allow_pickle=arr.dtype == object)


# --------------------------------------------------------------------------- evaluate
EVALUATIONS = (
    "denoise",
    "denoise-dynamic",
    "outliers",
    "saliency",
    "compress",
    "complete",
    "compress-animation",
    "register",
    "identify",
)


def cmd_evaluate(args) -> int:
    from ..datasets import data_dir

    data = Path(args.data) if args.data else data_dir(required=True)
    if not data.is_dir():
        raise _err(f"`--data` must be a folder; got {data}.")
    methods = args.methods.split(",") if args.methods else None
    protocol = _generality_options(args)
    if args.what == "denoise" and protocol is not None:
        from ..evaluate import denoise as ev

        res = ev.evaluate_generality(
            data, **protocol, **({"methods": methods} if methods else {}), out=args.out
        )
        print(ev.format_generality(res))
        return 0
    before = _outputs(args.out)
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
            mod = {"complete": "completion"}.get(args.what, args.what.replace("-", "_"))
            ev = importlib.import_module(f"spectrageo.evaluate.{mod}")
        except ModuleNotFoundError as exc:
            raise _err(f"no evaluation named {args.what!r}.") from exc
        rows = ev.evaluate(data, methods=methods, out=args.out)
    if not rows:  # nothing of this area under --data: empty tables help no one
        for f in _outputs(args.out) - before:
            f.unlink(missing_ok=True)
        raise _err(
            f"no {args.what} benchmark data found under {data} (its models and scans are "
            "read from the shared data folder's layout; see the README, Data and licences)."
        )
    print(ev.format_markdown(rows))
    return 0


def _outputs(out) -> set:
    """The files an evaluation writes for ``--out`` (``.md``, ``.csv``, ``.png``) that exist."""
    if not out:
        return set()
    base = Path(out)
    base = base.with_suffix("") if base.suffix in (".md", ".csv", ".png") else base
    return {f for f in (base.with_suffix(x) for x in (".md", ".csv", ".png")) if f.exists()}


def _generality_options(args) -> dict | None:
    """Keyword arguments of ``evaluate_generality`` from ``evaluate denoise --split ...``; None
    when no protocol option is given (the pairs evaluation runs as before)."""
    given = {
        "--levels": args.levels,
        "--max-vertices": args.max_vertices,
        "--models": args.models,
        "--cli-timing": args.cli_timing or None,
        "--repeat": args.repeat,
    }
    if args.split is None:
        used = [k for k, v in given.items() if v is not None]
        if used:
            raise _err(f"`{used[0]}` needs `--split tuning|validation|both` (evaluate denoise).")
        return None
    if args.what != "denoise":
        raise _err(f"`--split` applies to `evaluate denoise` only; got {args.what!r}.")
    opts: dict = {"split": args.split, "cli_timing": bool(args.cli_timing)}
    if args.repeat is not None:
        opts["repeat"] = args.repeat  # checked by evaluate_generality
    if args.levels:
        try:
            opts["levels"] = [float(x) for x in args.levels.split(",")]
        except ValueError as exc:
            raise _err(f"`--levels` must be comma-separated numbers; got {args.levels!r}.") from exc
    if args.max_vertices is not None:
        opts["max_vertices"] = args.max_vertices
    if args.models:
        opts["models"] = args.models.split(",")
    return opts


# --------------------------------------------------------------------------- demo
def cmd_demo(args) -> int:
    from ..noise._core import check_level
    from .demo import run_demo

    check_level(args.level)  # before the output folder is created
    if args.methods:
        from .. import denoise

        for m in args.methods.split(","):
            denoise.get(m)

    run_demo(
        out_dir=Path(args.out),
        level=args.level,
        seed=args.seed,
        methods=args.methods.split(",") if args.methods else None,
    )
    return 0


# --------------------------------------------------------------------------- help texts
#: ``command -> (description, example)`` shown by ``spectrageo COMMAND --help``.
HELP_TEXTS: dict[str, tuple[str, str]] = {
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
    "denoise": (
        "Denoise a mesh or a mesh animation. Seam copies and soup corners are processed welded\n"
        "and written back in the input's vertex order and count.",
        "spectrageo denoise noisy.obj clean.ply --method tsgsp\n"
        "spectrageo denoise crane_noisy.npz crane_clean.npz --method gft-rpca",
    ),
    "outliers": (
        "Remove outliers from a point cloud, the vertices of a mesh (faces of kept vertices are\n"
        "kept) or a point-cloud sequence. Masks and scores cover every input row.",
        "spectrageo outliers scan.pcd clean.pcd --method rpca --mask keep.npy",
    ),
    "robot": (
        "Consolidate a depth-camera cloud (Section 5.4.2): RPCA outlier removal, then bilateral\n"
        "filtering of the kept points along their normals over k-NN cells (Eq. 5.100-5.101).",
        "spectrageo robot scan.ply clean.ply --k 7\n"
        "spectrageo robot big.las clean.las --tile 500000 --workers 2",
    ),
    "evaluate": (
        "Run methods and peers over the shared benchmark data; prints markdown tables and, with\n"
        "--out FILE, writes FILE.md and FILE.csv.",
        "spectrageo evaluate denoise --out results/denoise",
    ),
    "demo": (
        "Seeded Gaussian noise on the embedded fandisk, every denoiser, a metrics table and\n"
        "meshes plus an error heatmap in the output folder.",
        "spectrageo demo --out spectrageo-demo --level 0.3",
    ),
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
    "view": (
        "Serve a local web viewer on 127.0.0.1 and open it in the browser. Files given here are\n"
        "loaded at start; more can be loaded from the page.",
        "spectrageo view model.ply noisy.ply",
    ),
}


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
    p.add_argument(
        "--no-weld",
        action="store_true",
        help="keep the corners of STL/soup triangles apart (default: welded)",
    )
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("convert", help="convert between formats (vertex order preserved)")
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument("--kind", choices=["mesh", "points", "animation", "sequence"], default=None)
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--weld",
        action="store_true",
        help="merge coincident vertices of any mesh (default: STL and triangle soups only)",
    )
    g.add_argument(
        "--no-weld", action="store_true", help="keep STL/soup corners apart (the raw soup)"
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

    from .. import denoise as _den

    static, dynamic = _den.available(), _den.dynamic_methods()
    presets = {m: _den.get(m).presets for m in static if _den.get(m).presets}
    p = sub.add_parser("denoise", help="denoise a mesh or a mesh animation")
    p.add_argument("input", help="mesh file, animation .npz or folder of numbered mesh frames")
    p.add_argument("output")
    p.add_argument(
        "--method",
        default="tsgsp",
        metavar="METHOD",
        help=f"meshes: {', '.join(static)}; animations also: {', '.join(dynamic)} "
        "(static methods run frame by frame)",
    )
    p.add_argument(
        "--preset",
        default=None,
        help="parameter preset: " + "; ".join(f"{m}: {', '.join(ps)}" for m, ps in presets.items()),
    )
    p.add_argument(
        "--pre", default=None, choices=["coarse"], help="run the TSGSP coarse step first"
    )
    p.add_argument(
        "--no-weld",
        action="store_true",
        help="process vertices as stored: no welding of STL/soup corners or seam copies "
        "(by default seams are processed welded and written back in the input's order)",
    )
    p.add_argument(
        "--weights",
        default=None,
        metavar="W.npz",
        help="weights of --method bm3d-cnn or dae (from `spectrageo train`; default: shipped)",
    )
    p.add_argument(
        "--train-frames",
        type=int,
        default=None,
        metavar="N",
        help="--method dae on an animation: train the autoencoders on its first N frames",
    )
    p.add_argument(
        "--motion",
        choices=["auto", "rigid", "none"],
        default=None,
        help="with --train-frames: turn other frames' normals by the local motion (rigid), not "
        "(none), or decide from the motion between training frames (auto, the default)",
    )
    p.add_argument(
        "--block-size",
        type=int,
        default=None,
        metavar="N",
        help="--method gft-rpca on an animation: denoise blocks of N consecutive frames "
        "independently (online mode; `spectrageo batch` runs one Dask task per block)",
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
        help="write the boolean keep mask to .npy: one entry per input row, in input order "
        "(True = kept; rows without coordinates, NaN in organized PCDs, are False)",
    )
    p.add_argument(
        "--scores",
        default=None,
        help="write per-point outlier scores to .npy, one per input row (inf for NaN rows)",
    )
    add_tile_options(p)
    p.add_argument(
        "--device",
        default="cpu",
        choices=["cpu", "cuda", "auto"],
        help="where the RPCA iterations run: cpu (numba, default), cuda (PyTorch on the GPU; "
        "scores within 1e-3 spacings of cpu), auto (cuda when a GPU is visible); also for "
        "every tile with --tile. --method sor/radius and point-cloud sequences run on the CPU",
    )
    p.set_defaults(func=cmd_outliers)

    p = sub.add_parser(
        "robot", help="RPCA outlier removal + bilateral filtering of a scan (Sec. 5.4.2)"
    )
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument("--k", type=int, default=7, help="neighbours of the filter cells (7)")
    p.add_argument(
        "--rpca-k", type=int, default=10, dest="rpca_k", help="neighbours of the RPCA step (10)"
    )
    p.add_argument(
        "--threshold", type=float, default=None, help="RPCA score threshold (default: automatic)"
    )
    p.add_argument("--sigma1", type=float, default=None, help="spatial kernel width")
    p.add_argument("--sigma2", type=float, default=None, help="range kernel width")
    p.add_argument("--n-iter", type=int, default=1, dest="n_iter", help="filter passes (1)")
    p.add_argument(
        "--mesh", action="store_true", help="write the kNN triangulation of the filtered points"
    )
    p.add_argument(
        "--mask", default=None, help="write the RPCA keep mask to .npy (one entry per input row)"
    )
    add_tile_options(p)
    p.set_defaults(func=cmd_robot)

    p = sub.add_parser("evaluate", help="run methods on the shared benchmark data and print tables")
    p.add_argument("what", choices=EVALUATIONS, metavar="AREA", help=" | ".join(EVALUATIONS))
    p.add_argument(
        "--data", default=None, help="data folder (default: $SPECTRAGEO_DATA or ../shared/data)"
    )
    p.add_argument("--methods", default=None, help="comma-separated method names")
    p.add_argument("--out", default=None, help="write FILE.md and FILE.csv")
    g = p.add_argument_group("denoise generality protocol (evaluate denoise only)")
    g.add_argument(
        "--split",
        default=None,
        choices=("tuning", "validation", "both"),
        help="run the protocol on this split instead of the shared pairs (also writes "
        "FILE_grid.csv and FILE.png)",
    )
    g.add_argument("--levels", default=None, help="noise levels, e.g. 0.1,0.3,0.5 (the default)")
    g.add_argument("--max-vertices", type=int, default=None, help="skip models with more vertices")
    g.add_argument("--models", default=None, help="comma-separated models, e.g. partLp,cad/joint")
    g.add_argument(
        "--cli-timing",
        action="store_true",
        help="also time `spectrageo denoise` processes for the package's methods",
    )
    g.add_argument(
        "--repeat",
        type=int,
        default=None,
        help="report the best of N timings of the package's methods (default 1)",
    )
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("demo", help="noise + every denoiser on the embedded fandisk, with metrics")
    p.add_argument(
        "--out", default="spectrageo-demo", help="output folder (default ./spectrageo-demo)"
    )
    p.add_argument(
        "--level", type=float, default=0.3, help="noise level relative to the mean edge length"
    )
    p.add_argument("--seed", type=seed_type, default=0)
    p.add_argument("--methods", default=None, help=f"comma-separated subset of {', '.join(static)}")
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
_COMMAND_MODULES = (
    "saliency_cmds",
    "view_cmd",
    "compress_cmds",
    "complete_cmds",
    "batch_cmds",
    "register_cmds",
    "identify_cmds",
    "learn_cmds",
)
