"""``spectrageo batch COMMAND INPUT... --out DIR``: a single-file command over many files on Dask.

Each ``batch COMMAND`` parser carries the options of ``spectrageo COMMAND`` (built from the same
:class:`~spectrageo.distributed.CommandSchema`, so the same names, defaults and checks) except
those that name one file per run, plus the batch options.
"""

from __future__ import annotations

import argparse
import sys

from ._common import add_schema_options

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
    """Add ``batch`` with one sub-parser per batch command, its options from the command's schema."""
    from ..distributed import COMMANDS

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
    for name, schema in COMMANDS.items():
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
        add_schema_options(bp, schema, per_file=False)
        defaults = {a.dest: a.default for a in bp._actions if a.dest != argparse.SUPPRESS}
        bp.set_defaults(func=cmd_batch, _defaults=defaults)
