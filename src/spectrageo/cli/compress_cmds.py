"""``spectrageo compress | decompress`` and ``spectrageo info FILE.sgc`` (thesis Section 5.2).

``compress`` runs :func:`spectrageo.distributed._run_codec.run_compress`; ``decompress`` and
``info`` read ``.sgc`` meshes through :func:`spectrageo.compress.decode` /
:func:`~spectrageo.compress.info` and ``.sga`` animations (Section 5.2.2) through
:func:`~spectrageo.compress.decode_animation`; every output is written atomically.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from .._errors import InvalidInputError
from ..distributed import COMMANDS
from ._common import add_schema_options, apply_help, check_outputs, status

HELP = {
    "compress": (
        "Compress a triangle mesh into a .sgc file: spectral (block spectral coding on\n"
        "overlapped submeshes, Sec. 5.2.1, progressive), feature (feature-aware delta\n"
        "coordinates, Algorithm 9), saliency (Algorithm 10) or predictive (grid quantisation\n"
        "and parallelogram prediction). The default, auto, keeps the smaller file of\n"
        "predictive and spectral at the target given (spectral without one). Vertex and face\n"
        "order are kept unless --reorder. --bpv\n"
        "counts the whole file; --error is the RMS vertex error as a fraction of the\n"
        "bounding-box diagonal; both are met within 5 %. --max-error bounds the largest vertex\n"
        "deviation, hence the symmetric Hausdorff distance (any bound with predictive).\n"
        "Animations (.npz or a folder of frames) go to a .sga file: trajectory PCA with the\n"
        "coefficients predicted along the mesh (pca-pred [default]; --reorder codes vertices and\n"
        "faces in the connectivity coder's order), eigen-trajectory coding of delta coordinates\n"
        "(Sec. 5.2.2: pca, pca-q, pca-qs, pca-qp, blocks), eigen-trajectories in the partitioned\n"
        "GFT basis (pca-spectral: Sec. 5.2.1 + 5.2.2) or the scalable layered streaming codec\n"
        "(Sec. 5.2.4: layered, one segment per frame); --bpvf is the whole file in bits per\n"
        "vertex per frame, --error the KG error in percent.",
        "spectrageo compress fandisk.off fandisk.sgc --bpv 20\n"
        "spectrageo compress part.obj part.sgc --method feature --error 0.002\n"
        "spectrageo compress part.obj part.sgc --max-error 1e-4 --reorder   # auto\n"
        "spectrageo compress part.obj part.sgc --method predictive --max-error 1e-4 --reorder\n"
        "spectrageo compress crane.npz crane.sga --method pca-qp --bpvf 4\n"
        "spectrageo compress frames/ anim.sga --error 0.1   # KG error in percent",
    ),
    "decompress": (
        "Decompress a .sgc file into any mesh format (.ply, .obj, .off, .stl). --partial decodes\n"
        "a file that was cut short (a progressive prefix) to a coarser mesh. A .sga animation\n"
        "decompresses into a .npz or a folder of frames; --partial keeps every complete block.",
        "spectrageo decompress fandisk.sgc fandisk.ply\nspectrageo decompress crane.sga crane.npz",
    ),
}


def _read_sgc(path: str) -> bytes:
    """The bytes of a .sgc / .sga file, gunzipped when its name ends with .gz."""
    from ..io._common import read_bytes, split_suffix

    p = Path(path)
    if p.is_dir():
        raise InvalidInputError(f"{path!r} is a folder, not a .sgc file.")
    if not p.exists():
        raise InvalidInputError(f"file not found: {p}")
    return read_bytes(p, split_suffix(p)[1])


def cmd_decompress(args) -> int:
    from .. import compress, io
    from ..geometry import Mesh

    check_outputs([args.input], [args.output])
    data = _read_sgc(args.input)
    if compress._sga_format.is_animation(data):
        return _decompress_animation(args, data)
    t0 = time.perf_counter()
    V, F = compress.decode(data, partial=args.partial)
    dt = time.perf_counter() - t0
    io.write(args.output, Mesh(V, F))
    status(f"wrote {args.output}: {V.shape[0]} vertices, {F.shape[0]} faces, {dt:.2f} s")
    return 0


def _decompress_animation(args, data: bytes) -> int:
    from .. import compress, io
    from ..geometry import MeshAnimation

    t0 = time.perf_counter()
    frames, F = compress.decode_animation(data, partial=args.partial)
    dt = time.perf_counter() - t0
    msg = f"wrote {args.output}: {frames.shape[0]} frames of {frames.shape[1]} vertices"
    if args.partial:
        # the frame count the header announces (every stream kind's state carries it: the
        # layered one as ``n_frames``, the others in their ``params``)
        dec = compress.StreamDecoder()
        dec.feed(data)
        st = dec.state
        total = 0
        if st is not None:
            total = getattr(st, "n_frames", None)
            if total is None:
                total = st.params.n_frames
        if total and total > frames.shape[0]:
            msg += f" ({total - frames.shape[0]} of {total} frames missing: the file is cut short)"
    io.write(args.output, MeshAnimation(frames, F))
    status(f"{msg}, {dt:.2f} s ({1e3 * dt / frames.shape[0]:.1f} ms/frame)")
    return 0


def cmd_info_sgc(args) -> int:
    """``spectrageo info FILE.sgc [--json]`` (called by ``info`` for .sgc files)."""
    from .. import compress

    data = _read_sgc(args.file)
    name = Path(args.file).name
    try:
        d = {"file": str(args.file), **compress.info(data)}
    except InvalidInputError as mesh_err:  # an animation file (.sga): its own header
        try:
            d = {"file": str(args.file), **compress.info_animation(data)}
        except InvalidInputError as anim_err:
            if compress._sga_format.is_animation(data) or str(args.file).lower().endswith(".sga"):
                raise InvalidInputError(f"{name}: {anim_err}") from anim_err
            # neither: report it as the mesh file it is named
            raise InvalidInputError(f"{name}: {mesh_err}") from None
    if args.json:
        print(json.dumps(d, indent=2))
    else:
        for k, v in d.items():
            if isinstance(v, dict):
                v = ", ".join(f"{a}={b}" for a, b in v.items())
            elif isinstance(v, float):
                v = f"{v:.4g}"
            print(f"{k:>24}: {v}")
    return 0


def register(sub) -> None:
    p = sub.add_parser(
        "compress", help="compress a mesh (.sgc) or an animation (.sga) (Sec. 5.2.1-5.2.3)"
    )
    p.add_argument("input", help="mesh file, or animation (.npz or a folder of frames)")
    p.add_argument("output", help="OUT.sgc (mesh) or OUT.sga (animation)")
    add_schema_options(p, COMMANDS["compress"])
    p.set_defaults(func=COMMANDS["compress"].run)

    p = sub.add_parser("decompress", help="decompress a .sgc file into a mesh file")
    p.add_argument("input", help="IN.sgc or IN.sga")
    p.add_argument(
        "output", help="mesh file (.ply, .obj, .off, .stl); animations: .npz or a folder"
    )
    p.add_argument(
        "--partial",
        action="store_true",
        help="decode a truncated file (progressive prefix; complete animation blocks)",
    )
    p.set_defaults(func=cmd_decompress)

    apply_help(sub, HELP)


__all__ = ["register"]
