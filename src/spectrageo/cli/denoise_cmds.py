"""``spectrageo denoise | outliers | robot``: mesh and animation denoising, outlier removal and the
robot pipeline (thesis Sections 4, 5.1 and 5.4), in memory or tiled out of core on Dask."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from ..distributed import COMMANDS
from ._common import (
    add_schema_options,
    add_tile_options,
    apply_help,
    check_outputs,
    check_tile,
    err,
    status,
)
from ._common import read_reported as _read
from ._common import save_npy as _save_npy

HELP = {
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
}


def cmd_outliers(args) -> int:
    """``spectrageo outliers IN OUT``: in memory, or tiled on Dask with ``--tile``."""
    if getattr(args, "tile", None) is None:
        return COMMANDS["outliers"].run(args)
    check_outputs([args.input], [args.output, args.mask, args.scores])
    return cmd_outliers_tiled(args)


def cmd_robot(args) -> int:
    """``spectrageo robot IN OUT``: :func:`spectrageo.outliers.robot_pipeline` (Section 5.4.2)."""
    from .. import io, outliers
    from ..geometry import Mesh, PointCloud

    check_outputs([args.input], [args.output, args.mask])
    if getattr(args, "tile", None) is not None:  # out-of-core on Dask (issue 21)
        return cmd_robot_tiled(args)
    obj, _rep = _read(args.input)
    if isinstance(obj, Mesh):
        cloud = PointCloud(
            obj.vertices, obj.vertex_normals, obj.vertex_colors, obj.vertex_attributes
        )
    elif isinstance(obj, PointCloud):
        cloud = obj
    else:
        raise err(f"{Path(args.input).name}: robot needs a point cloud or a mesh's vertices.")
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
    status(
        f"wrote {args.output}: kept {int(np.sum(res.keep))} of {cloud.n_points} points, "
        f"filtered ({time.perf_counter() - t0:.2f} s)"
    )
    return 0


def cmd_outliers_tiled(args) -> int:
    """``spectrageo outliers IN OUT --tile N``: :func:`spectrageo.distributed.remove_outliers_tiled`."""
    from .. import _progress, distributed

    if args.tile is None or args.tile <= 0:
        raise InvalidInputError(f"`tile` must be a positive number of points; got {args.tile}.")
    if getattr(args, "viewpoint", None) is not None:
        raise InvalidInputError("--viewpoint is not applied per tile; run without --tile.")
    want = bool(args.mask or args.scores)
    device = getattr(args, "device", "cpu")
    extra = {}
    if args.method == "rpca" and device != "cpu":
        extra["device"] = device  # each tile's RPCA iterations (rpca_scores's device)
    elif args.method != "rpca" and device == "cuda":
        raise InvalidInputError(
            f"--device cuda applies to --method rpca only; --method {args.method} runs on the CPU."
        )
    res = distributed.remove_outliers_tiled(
        args.input,
        args.output,
        distributed.TileOptions(
            args.tile,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=_progress.progress_enabled(),
        ),
        method=args.method,
        k=args.k,
        threshold=args.threshold,
        return_arrays=want,
        **extra,
    )
    if args.mask:
        _save_npy(args.mask, np.asarray(res.keep))
    if args.scores:
        _save_npy(args.scores, np.asarray(res.scores))
    i = res.info
    status(
        f"wrote {args.output}: kept {res.n_kept} of {res.n_points} points ({args.method}, "
        f"{res.n_tiles} tiles of <= {i['tile_points_max']} points, halo +"
        f"{100 * i['halo_fraction_mean']:.0f} %, {i['n_workers']} workers, "
        f"{i['time_total_s']:.2f} s)"
    )
    return 0


def cmd_robot_tiled(args) -> int:
    """``spectrageo robot IN OUT --tile N``: :func:`spectrageo.distributed.robot_denoise_tiled`."""
    from .. import _progress, distributed

    check_tile(args)
    if args.mesh:
        raise InvalidInputError(
            "--mesh is not available with --tile (the triangulation needs the whole cloud)."
        )
    res = distributed.robot_denoise_tiled(
        args.input,
        args.output,
        distributed.TileOptions(
            args.tile,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=_progress.progress_enabled(),
        ),
        k=args.k,
        threshold=args.threshold,
        rpca_k=args.rpca_k,
        sigma1=args.sigma1,
        sigma2=args.sigma2,
        n_iter=args.n_iter,
        return_arrays=bool(args.mask),
    )
    if args.mask:
        _save_npy(args.mask, np.asarray(res.keep))
    i = res.info
    status(
        f"wrote {args.output}: kept {res.n_kept} of {res.n_points} points, filtered "
        f"({res.n_tiles} tiles of <= {i['tile_points_max']} points, halo +"
        f"{100 * i['halo_fraction_mean']:.0f} %, {i['n_workers']} workers, "
        f"{i['time_total_s']:.2f} s)"
    )
    return 0


def register(sub) -> None:
    """Add ``denoise``, ``outliers`` and ``robot``."""
    p = sub.add_parser("denoise", help="denoise a mesh or a mesh animation")
    p.add_argument("input", help="mesh file, animation .npz or folder of numbered mesh frames")
    p.add_argument("output")
    add_schema_options(p, COMMANDS["denoise"])
    p.set_defaults(func=COMMANDS["denoise"].run)

    p = sub.add_parser(
        "outliers", help="remove outliers from a point cloud or a point-cloud sequence"
    )
    p.add_argument("input")
    p.add_argument("output")
    add_schema_options(p, COMMANDS["outliers"])
    add_tile_options(p)
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
    apply_help(sub, HELP)
