"""``spectrageo train dae|bm3d-cnn`` (thesis Sections 5.1.3 and 5.1.4, issue 20).

Thin layer over :func:`spectrageo.learn.train.train_dae` and
:func:`spectrageo.learn.train.train_bm3d_cnn`; needs PyTorch (``pip install spectrageo[learn]``).
The weights are written atomically, with a training report next to them (``.json``, ``.md`` and,
with matplotlib, ``_loss.png``).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

from .._errors import InvalidInputError
from ._argtypes import seed_type
from ._common import apply_help, is_quiet, status

HELP = {
    "train": (
        "Train the weights of a learned denoiser on clean meshes of a data folder corrupted by\n"
        "the noise generator (Gaussian along normals at several levels): bm3d-cnn (block-matching\n"
        "3D CNN, Sec. 5.1.4) or dae (content-wise denoising autoencoders, Sec. 5.1.3). --data is\n"
        "the shared data folder; the default training meshes are held out of the denoising\n"
        "protocol's validation split and benchmark pairs. Writes W.npz and a report (W.json,\n"
        "W.md, W_loss.png). Needs PyTorch: pip install spectrageo[learn].",
        "spectrageo train bm3d-cnn --data ../shared/data --out bm3d.npz --epochs 4\n"
        "spectrageo denoise noisy.obj clean.ply --method bm3d-cnn --weights bm3d.npz",
    ),
}


def cmd_train(args) -> int:
    if importlib.util.find_spec("torch") is None:
        raise InvalidInputError("`spectrageo train` needs PyTorch: install spectrageo[learn].")
    data = Path(args.data)
    if not data.is_dir():
        raise InvalidInputError(f"--data must be a folder; got {args.data!r}.")
    out = Path(args.out)
    if out.suffix != ".npz":
        raise InvalidInputError(f"--out must end in .npz; got {args.out!r}.")
    if args.epochs is not None and args.epochs < 1:
        raise InvalidInputError(f"--epochs must be >= 1; got {args.epochs}.")
    from ..learn import train

    log = None if is_quiet() else status
    kw = {"device": args.device, "seed": args.seed, "threads": args.threads}
    if args.epochs is not None:
        kw["epochs"] = args.epochs
    if args.meshes:
        kw["meshes"] = [m.strip() for m in args.meshes.split(",") if m.strip()]
    if args.model == "bm3d-cnn":
        if args.stages is not None:
            kw["n_stages"] = args.stages
        summary = train.train_bm3d_cnn(data, out, train.BM3DCNNTrainOptions(**kw), log=log)
    else:
        if args.stages is not None:
            raise InvalidInputError("--stages applies to bm3d-cnn only.")
        summary = train.train_dae(data, out, train.DAETrainOptions(**kw), log=log)
    val = summary.get("validation") or []
    text = ", ".join(f"{r['level']:g}: {r['input_theta']:.1f} -> {r['theta']:.1f} deg" for r in val)
    status(
        f"wrote {out} ({summary['meta']['train_seconds']:.0f} s)"
        + (f"; validation theta on {train.REPORT_MESH} {text}" if text else "")
    )
    return 0


def register(sub) -> None:
    p = sub.add_parser("train", help="train the weights of a learned denoiser (needs torch)")
    p.add_argument("model", choices=["dae", "bm3d-cnn"])
    p.add_argument("--data", required=True, help="data folder (the shared data)")
    p.add_argument("--out", required=True, metavar="WEIGHTS.npz")
    p.add_argument("--epochs", type=int, default=None, help="epochs per model / stage")
    p.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    p.add_argument("--seed", type=seed_type, default=0)
    p.add_argument("--stages", type=int, default=None, help="bm3d-cnn cascade stages")
    p.add_argument("--threads", type=int, default=None, help="CPU threads of torch")
    p.add_argument(
        "--meshes",
        default=None,
        metavar="REL,REL",
        help="comma-separated training meshes relative to --data "
        "(default: spectrageo.learn.train.TRAIN_MESHES)",
    )
    p.set_defaults(func=cmd_train)
    apply_help(sub, HELP)


__all__ = ["register"]
