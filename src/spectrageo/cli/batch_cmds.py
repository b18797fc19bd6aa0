"""``spectrageo batch COMMAND INPUT... --out DIR``: a single-file command over many files on Dask.

Each ``batch COMMAND`` parser carries the options of ``spectrageo COMMAND`` itself (the same
argparse actions, so the same names, defaults and checks) plus the batch options.
"""

from __future__ import annotations

import argparse
import sys

from .._errors import InvalidInputError

_BATCH_DESTS = ("inputs", "out", "workers", "scheduler", "resume", "suffix", "summary", "quiet")


def cmd_batch(args) -> int:
    from .. import _progress, distributed

    _progress_on = _progress.progress_enabled() and not args.quiet
    out_attr = distributed.BATCH_COMMANDS[args.batch_command]
    options = {
        k: v
        for k, v in vars(args).items()
        if k
        not in _BATCH_DESTS + ("func", "command", "batch_command", "input", "_defaults", out_attr)
        and v != args._defaults.get(k)
    }
    recs = distributed.batch(
        args.batch_command,
        args.inputs,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        resume=args.resume,
        suffix=args.suffix,
        summary=args.summary,
        progress=_progress_on,
        **options,
    )
    n = {s: sum(r["status"] == s for r in recs) for s in ("ok", "failed", "skipped")}
    if not args.quiet:
        for r in recs:
            if r["status"] == "failed":
                print(f"failed: {r['input']}: {r.get('error', '')}", file=sys.stderr)
        summary = args.summary or f"{args.out}/batch-summary.json"
        print(
            f"batch {args.batch_command}: {n['ok']} ok, {n['failed']} failed, {n['skipped']} "
            f"skipped; summary {summary}",
            file=sys.stderr,
        )
    return 1 if n["failed"] else 0


def register(sub) -> None:
    """Add ``batch`` with one sub-parser per batch command (registered after those commands)."""
    from ..distributed._batch import _PER_FILE_OPTIONS, BATCH_COMMANDS

    p = sub.add_parser(
        "batch",
        help="run denoise/outliers/saliency/compress/complete/convert over many files on Dask",
        description="Run a single-file command over files, globs or folders, one Dask task per "
        "file, outputs named after the inputs in --out, a JSON summary per file.",
        epilog="example:\n  spectrageo batch denoise 'scans/*.ply' --out denoised --workers 4\n"
        "  spectrageo batch outliers clouds/ --out clean --resume --method sor",
    )
    bsub = p.add_subparsers(dest="batch_command", metavar="COMMAND", parser_class=type(p))
    bsub.required = True
    for name, out_attr in BATCH_COMMANDS.items():
        src = sub.choices.get(name)
        if src is None:  # e.g. `complete` not installed in this version
            continue
        bp = bsub.add_parser(name, help=f"spectrageo {name} over many files")
        bp.add_argument("inputs", nargs="+", metavar="INPUT", help="files, glob patterns, folders")
        bp.add_argument("--out", required=True, metavar="DIR", help="output folder")
        bp.add_argument(
            "--workers", type=int, default=None, help="local cluster workers (default: cores)"
        )
        bp.add_argument(
            "--scheduler", default=None, metavar="ADDRESS", help="a running Dask scheduler"
        )
        bp.add_argument("--resume", action="store_true", help="skip inputs whose output exists")
        bp.add_argument(
            "--suffix",
            default=None,
            help="output format, e.g. .ply (default: the input's; required for convert)",
        )
        bp.add_argument(
            "--summary", default=None, help="JSON summary (default DIR/batch-summary.json)"
        )
        bp.add_argument("-q", "--quiet", action="store_true", help="no progress and no status")
        skip = {"help", "input", out_attr, "quiet", *(_PER_FILE_OPTIONS.get(name, ()))}
        skip |= {"tile", "scheduler", "workers"}  # outliers' own --tile options
        grouped = {id(a) for g in src._mutually_exclusive_groups for a in g._group_actions}
        for g in src._mutually_exclusive_groups:
            ng = bp.add_mutually_exclusive_group()
            for a in g._group_actions:
                if a.dest not in skip:
                    ng._add_action(a)
        for a in src._actions:
            if a.dest in skip or id(a) in grouped or not a.option_strings:
                continue
            bp._add_action(a)
        defaults = {a.dest: a.default for a in bp._actions if a.dest != argparse.SUPPRESS}
        bp.set_defaults(func=cmd_batch, _defaults=defaults)


def cmd_outliers_tiled(args) -> int:
    """``spectrageo outliers IN OUT --tile N``: :func:`spectrageo.distributed.remove_outliers_tiled`."""
    import numpy as np

    from .. import _progress, distributed
    from . import commands

    if args.tile is None or args.tile <= 0:
        raise InvalidInputError(f"`tile` must be a positive number of points; got {args.tile}.")
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
        tile=args.tile,
        method=args.method,
        k=args.k,
        threshold=args.threshold,
        workers=args.workers,
        scheduler=args.scheduler,
        return_arrays=want,
        progress=_progress.progress_enabled(),
        **extra,
    )
    if args.mask:
        commands._save_npy(args.mask, np.asarray(res.keep))
    if args.scores:
        commands._save_npy(args.scores, np.asarray(res.scores))
    i = res.info
    commands._status(
        f"wrote {args.output}: kept {res.n_kept} of {res.n_points} points ({args.method}, "
        f"{res.n_tiles} tiles of <= {i['tile_points_max']} points, halo +"
        f"{100 * i['halo_fraction_mean']:.0f} %, {i['n_workers']} workers, "
        f"{i['time_total_s']:.2f} s)"
    )
    return 0


def _check_tile(args) -> None:
    if args.tile is None or args.tile <= 0:
        raise InvalidInputError(f"`tile` must be a positive number of points; got {args.tile}.")


def cmd_saliency_tiled(args) -> int:
    """``spectrageo saliency IN --out OUT --tile N``: :func:`spectrageo.distributed.saliency_tiled`."""
    from .. import _progress, distributed
    from . import commands

    _check_tile(args)
    if args.per == "face":
        raise InvalidInputError("a point cloud has no faces; use --per vertex.")
    commands._check_outputs([args.input], [args.out])
    res = distributed.saliency_tiled(
        args.input,
        args.out,
        tile=args.tile,
        k=args.k,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=_progress.progress_enabled(),
    )
    i = res.info
    commands._status(
        f"wrote {args.out} ({res.n_points} values, {res.n_tiles} tiles of <= "
        f"{i['tile_points_max']} points, halo +{100 * i['halo_fraction_mean']:.0f} %, "
        f"{i['n_workers']} workers, {i['time_total_s']:.2f} s)"
    )
    return 0


def cmd_robot_tiled(args) -> int:
    """``spectrageo robot IN OUT --tile N``: :func:`spectrageo.distributed.robot_denoise_tiled`."""
    import numpy as np

    from .. import _progress, distributed
    from . import commands

    _check_tile(args)
    if args.mesh:
        raise InvalidInputError(
            "--mesh is not available with --tile (the triangulation needs the whole cloud)."
        )
    res = distributed.robot_denoise_tiled(
        args.input,
        args.output,
        tile=args.tile,
        k=args.k,
        threshold=args.threshold,
        rpca_k=args.rpca_k,
        sigma1=args.sigma1,
        sigma2=args.sigma2,
        n_iter=args.n_iter,
        workers=args.workers,
        scheduler=args.scheduler,
        return_arrays=bool(args.mask),
        progress=_progress.progress_enabled(),
    )
    if args.mask:
        commands._save_npy(args.mask, np.asarray(res.keep))
    i = res.info
    commands._status(
        f"wrote {args.output}: kept {res.n_kept} of {res.n_points} points, filtered "
        f"({res.n_tiles} tiles of <= {i['tile_points_max']} points, halo +"
        f"{100 * i['halo_fraction_mean']:.0f} %, {i['n_workers']} workers, "
        f"{i['time_total_s']:.2f} s)"
    )
    return 0


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
