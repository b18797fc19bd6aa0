"""Single-file runners of ``convert``, ``denoise``, ``outliers`` and ``saliency``.

Each ``run_*`` takes the command's namespace (``input``, the output path and the options of its
:class:`~spectrageo.distributed._schema.CommandSchema`), writes the output atomically, prints its
status lines on stderr and returns the exit status.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from ._files import check_outputs, read_reported, save_npy, status
from ._schema import describe
from ._values import value_suffix, write_values


def run_convert(args) -> int:
    from .. import io
    from ..geometry import Mesh
    from ..io._api import _MESH_WRITE, _POINTS_WRITE
    from ..io._common import split_suffix

    check_outputs([args.input], [args.output])
    weld = True if args.weld else False if args.no_weld else None
    obj, _rep = read_reported(args.input, kind=args.kind, weld=weld, no_weld_option=True)
    suffix = split_suffix(Path(args.output))[0]
    if isinstance(obj, Mesh) and suffix in _POINTS_WRITE and suffix not in _MESH_WRITE:
        raise InvalidInputError(
            f"{Path(args.output).name}: {suffix} holds points only, and {Path(args.input).name} "
            f"is a mesh with {obj.n_faces} faces; pass --kind points to write its vertices "
            "without the faces, or choose a mesh format (.ply, .obj, .off, .stl)."
        )
    kw = {}
    if args.ascii:
        kw["binary"] = False
    io.write(args.output, obj, **kw)
    status(f"wrote {args.output} ({describe(obj)['kind']})")
    return 0


def run_denoise(args) -> int:
    from .. import denoise, io
    from .._progress import activity, progress
    from ..denoise._guard import is_folded
    from ..geometry import Mesh, MeshAnimation, PointCloud

    check_outputs([args.input], [args.output])
    obj, _rep = read_reported(args.input, weld=False if args.no_weld else None, no_weld_option=True)
    opts = {}
    if args.preset:
        opts["preset"] = args.preset
    if args.pre:
        opts["pre"] = args.pre
    learned = ("bm3d-cnn", "dae")  # spectrageo.learn (issue 20)
    if args.weights is not None and args.method not in learned:
        raise InvalidInputError(
            f"--weights applies to the learned methods {', '.join(learned)}; got {args.method!r}."
        )
    if args.weights is not None:
        opts["weights"] = args.weights
    if args.train_frames is not None and args.method != "dae":
        raise InvalidInputError(
            f"--train-frames applies to --method dae only; got {args.method!r}."
        )
    motion = getattr(args, "motion", None)
    if motion is not None and args.train_frames is None:
        raise InvalidInputError("--motion applies to --method dae with --train-frames only.")
    block_size = getattr(args, "block_size", None)
    if block_size is not None and args.method != "gft-rpca":
        raise InvalidInputError(
            f"--block-size applies to --method gft-rpca only; got {args.method!r}."
        )
    t0 = time.perf_counter()
    if isinstance(obj, Mesh) and args.train_frames is not None:
        raise InvalidInputError(
            "--train-frames applies to animations (.npz or frame folders), not to a mesh."
        )
    if isinstance(obj, Mesh) and block_size is not None:
        raise InvalidInputError(
            "--block-size applies to animations (.npz or frame folders), not to a mesh."
        )
    if isinstance(obj, Mesh):
        with activity(f"denoise {args.method} ({obj.n_vertices} vertices)"):
            Vd = denoise.denoise(
                obj.vertices, obj.faces, method=args.method, weld=not args.no_weld, **opts
            )
        out = obj.with_vertices(Vd)
        if np.array_equal(Vd, obj.vertices):
            # the do-no-harm gate (spectrageo.denoise._guard) found no noise, or only detail
            from ..denoise._guard import coarse_shape, has_shared_edge
            from ..geometry.repair import degenerate_faces

            if degenerate_faces(obj.vertices, obj.faces).all():
                status(
                    "no face of non-zero area (the vertices lie on one point or one line), "
                    "nothing to filter: the vertices are written unchanged"
                )
            elif not has_shared_edge(obj.faces):
                status(
                    "separate triangles (no edge shared by two faces), nothing to filter: the "
                    "vertices are written unchanged"
                )
            elif coarse_shape(obj.vertices, obj.faces).coarse:
                status(
                    "coarse mesh (it turns by more per edge than noise would, coherently between "
                    "neighbours: Eqs. N11-N13 of spectrageo.denoise._guard), no noise found: the "
                    "vertices are written unchanged"
                )
            else:
                status("no noise found: the vertices are written unchanged")
        elif args.method == "tsgsp" and is_folded(obj.vertices, obj.faces):
            # the gate's decision on the mesh as given (the reader has welded any soup)
            status(
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
        raise InvalidInputError(
            f"{Path(args.input).name} is a {what} (no faces); denoise needs a mesh or a mesh "
            "animation. For point clouds use `spectrageo outliers` (smoothing: --method rpca)."
        )
    io.write(args.output, out)
    status(f"wrote {args.output} ({args.method}, {time.perf_counter() - t0:.2f} s)")
    return 0


def run_outliers(args) -> int:
    from .. import io, outliers
    from .._progress import activity
    from ..geometry import Mesh, PointCloud, PointCloudSequence

    check_outputs([args.input], [args.output, args.mask, args.scores])
    obj, rep = read_reported(args.input, nan_points="drop")
    opts = {"method": args.method, "k": args.k, "device": getattr(args, "device", "cpu")}
    if args.threshold is not None:
        opts["threshold"] = args.threshold
    vp = getattr(args, "viewpoint", None)
    if vp is not None and isinstance(obj, PointCloudSequence):
        raise InvalidInputError("--viewpoint applies to single point clouds, not sequences.")
    if not isinstance(obj, PointCloudSequence):  # --viewpoint, or a PCD's VIEWPOINT and grid
        scan = outliers.scan_options(args.input, obj, vp, args.method)
        if scan is not None:
            opts["options"] = scan
    if isinstance(obj, PointCloudSequence):
        if args.method != "rpca":
            raise InvalidInputError("sequences are cleaned with --method rpca (Section 5.4.3).")
        if args.scores:
            raise InvalidInputError(
                "--scores is written for single point clouds, not for sequences."
            )
        if getattr(args, "device", "cpu") == "cuda":
            raise InvalidInputError(
                "sequences are cleaned on the CPU; --device cuda applies to single clouds."
            )
        with activity(f"outliers rpca ({obj.n_frames} frames)"):
            res = outliers.clean_sequence(
                obj, k=args.k, **({"tau": args.threshold} if args.threshold else {})
            )
        io.write(args.output, res.frames)
        keep = np.array(res.keep, dtype=object) if not _same_len(res.keep) else np.stack(res.keep)
        if args.mask:
            save_npy(args.mask, keep)
        status(f"wrote {args.output} ({obj.n_frames} frames)")
        return 0
    if isinstance(obj, Mesh):
        cloud = PointCloud(
            obj.vertices, obj.vertex_normals, obj.vertex_colors, obj.vertex_attributes
        )
    elif isinstance(obj, PointCloud):
        cloud = obj
    else:
        raise InvalidInputError(
            f"{Path(args.input).name} is a mesh animation; outliers needs a point cloud, a mesh "
            "or a point-cloud sequence."
        )
    with activity(f"outliers {args.method} ({cloud.n_points} points)"):
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
        save_npy(args.mask, keep)
    if args.scores:
        save_npy(args.scores, scores)
    if args.method == "rpca":
        i = res.info
        extra += (
            f"; threshold {res.threshold:.3g} spacings ({i.get('threshold_rule')}), "
            f"{i.get('n_cluster_outliers', 0)} in small outlier clusters, estimated "
            f"contamination {100 * i.get('contamination', 0.0):.1f} %"
        )
    # of the rows the mask covers: every input row, or the vertices a triangle soup welded into
    status(
        f"wrote {args.output}: kept {int(np.sum(res.keep))} of {keep.shape[0]} points "
        f"({args.method}){extra}"
    )
    return 0


def _same_len(arrs) -> bool:
    return len({len(a) for a in arrs}) <= 1


def run_saliency(args) -> int:
    from .. import io, saliency
    from .._progress import activity
    from ..geometry import Mesh, MeshAnimation, PointCloud

    value_suffix(args.out)
    obj, rep = io.read_with_report(args.input, nan_points="drop")
    t0 = time.perf_counter()
    if isinstance(obj, Mesh):
        with activity(f"saliency {args.method} ({obj.n_vertices} vertices)"):
            s = saliency.saliency(
                obj.vertices,
                obj.faces,
                saliency.SaliencyOptions(k=args.k, fast=args.fast),
                method=args.method,
                per=args.per,
            )
        write_values(args.out, s, geometry=obj, per=args.per, name="saliency")
    elif isinstance(obj, PointCloud):
        if args.per == "face":
            raise InvalidInputError("a point cloud has no faces; use --per vertex.")
        with activity(f"saliency ({obj.n_points} points)"):
            s = saliency.pointcloud_saliency(obj.points, k=args.k)
        if rep.source_index is not None and value_suffix(args.out) != ".ply":
            # one value per input row, as the outlier masks: NaN where a row (an organized
            # scan's missing measurement) had no coordinates; a .ply holds the points kept
            full = np.full(rep.n_input_vertices, np.nan)
            full[rep.source_index] = s
            s = full
            status(
                f"{rep.n_nonfinite_rows} rows without coordinates (NaN): saliency NaN", always=True
            )
        write_values(args.out, s, geometry=obj, name="saliency")
    elif isinstance(obj, MeshAnimation):
        if args.per == "face":
            raise InvalidInputError("animations are mapped per vertex; use --per vertex.")
        if value_suffix(args.out) == ".ply":
            raise InvalidInputError("an animation map is (frames, vertices): use .npy or .csv.")
        with activity(f"saliency {args.method} ({obj.n_frames} frames)"):
            res = saliency.animation_saliency(
                obj.frames, obj.faces, saliency.SaliencyOptions(k=args.k), method=args.method
            )
        s = res.values
        write_values(args.out, s, name="saliency")
        status(
            f"recomputed {100 * res.recomputed_fraction[1:].mean():.1f} % of the vertices per frame"
            if obj.n_frames > 1
            else "one frame",
            always=True,
        )
    else:
        raise InvalidInputError(
            f"`saliency` needs a mesh or a point cloud; got {type(obj).__name__}."
        )
    status(
        f"wrote {args.out} ({s.shape[-1]} values, {time.perf_counter() - t0:.2f} s)", always=True
    )
    return 0
