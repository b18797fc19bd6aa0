"""Schemas of the single-file commands that :func:`spectrageo.distributed.batch` runs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ._run_codec import ANIM_METHODS, MESH_METHODS, run_complete, run_compress
from ._run_files import run_convert, run_denoise, run_outliers, run_saliency
from ._schema import CommandSchema, Option, describe

__all__ = ["COMMANDS"]

_KINDS = ("mesh", "points", "animation", "sequence")
_SALIENCY_METHODS = ("combined", "spectral", "geometric")


# ----------------------------------------------------------------------------- results
def _geometry_result(path: Path, mask: Path | None) -> dict[str, Any]:
    from .. import io

    d = describe(io.read(path))
    keys = ("kind", "n_vertices", "n_faces", "n_points", "n_frames")
    return {k: d[k] for k in keys if k in d}


def _outliers_result(path: Path, mask: Path | None) -> dict[str, Any]:
    import numpy as np

    if mask is None or not mask.exists():
        return _geometry_result(path, mask)
    keep = np.load(mask, allow_pickle=True)
    mask.unlink()
    if keep.dtype == bool:
        return {"n_points": int(keep.size), "n_kept": int(keep.sum())}
    return {}


def _compress_result(path: Path, mask: Path | None) -> dict[str, Any]:
    from .. import compress

    data = path.read_bytes()
    d = compress.info_animation(data) if path.suffix == ".sga" else compress.info(data)
    return {k: v for k, v in d.items() if isinstance(v, int | float | str | bool)}


def _saliency_result(path: Path, mask: Path | None) -> dict[str, Any]:
    import numpy as np

    if path.suffix.lower() != ".npy":
        return _geometry_result(path, mask)
    s = np.load(path)
    return {"n_values": int(s.size), "min": float(s.min()), "max": float(s.max())}


# ----------------------------------------------------------------------------- dynamic help
def _denoise_methods_help() -> str:
    from .. import denoise

    return (
        f"meshes: {', '.join(denoise.available())}; animations also: "
        f"{', '.join(denoise.dynamic_methods())} (static methods run frame by frame)"
    )


def _denoise_presets_help() -> str:
    from .. import denoise

    presets = {m: denoise.get(m).presets for m in denoise.available() if denoise.get(m).presets}
    return "parameter preset: " + "; ".join(f"{m}: {', '.join(ps)}" for m, ps in presets.items())


def _compress_methods() -> list[str]:
    from .. import compress

    return list(compress.ENCODE_METHODS) + list(compress.ANIMATION_METHODS)


# ----------------------------------------------------------------------------- the schemas
_NO_WELD_HELP = "keep STL/soup corners apart (the raw soup)"

CONVERT = CommandSchema(
    name="convert",
    run=run_convert,
    output="output",
    result=_geometry_result,
    options=(
        Option("kind", ("--kind",), choices=_KINDS),
        Option(
            "weld", ("--weld",), switch=True, group="weld",
            help="merge coincident vertices of any mesh (default: STL and triangle soups only)",
        ),
        Option("no_weld", ("--no-weld",), switch=True, group="weld", help=_NO_WELD_HELP),
        Option(
            "ascii", ("--ascii",), switch=True,
            help="write text variants (PLY, PCD) instead of binary",
        ),
    ),
)  # fmt: skip

DENOISE = CommandSchema(
    name="denoise",
    run=run_denoise,
    output="output",
    result=_geometry_result,
    options=(
        Option("method", ("--method",), default="tsgsp", metavar="METHOD", help=_denoise_methods_help),
        Option("preset", ("--preset",), help=_denoise_presets_help),
        Option("pre", ("--pre",), choices=("coarse",), help="run the TSGSP coarse step first"),
        Option(
            "no_weld", ("--no-weld",), switch=True,
            help="process vertices as stored: no welding of STL/soup corners or seam copies "
            "(by default seams are processed welded and written back in the input's order)",
        ),
        Option(
            "weights", ("--weights",), metavar="W.npz",
            help="weights of --method bm3d-cnn or dae (from `spectrageo train`; default: shipped)",
        ),
        Option(
            "train_frames", ("--train-frames",), type=int, metavar="N",
            help="--method dae on an animation: train the autoencoders on its first N frames",
        ),
        Option(
            "motion", ("--motion",), choices=("auto", "rigid", "none"),
            help="with --train-frames: turn other frames' normals by the local motion (rigid), "
            "not (none), or decide from the motion between training frames (auto, the default)",
        ),
        Option(
            "block_size", ("--block-size",), type=int, metavar="N",
            help="--method gft-rpca on an animation: denoise blocks of N consecutive frames "
            "independently (online mode; `spectrageo batch` runs one Dask task per block)",
        ),
    ),
)  # fmt: skip

OUTLIERS = CommandSchema(
    name="outliers",
    run=run_outliers,
    output="output",
    result=_outliers_result,
    keep_mask="mask",
    options=(
        Option("method", ("--method",), default="rpca", choices=("rpca", "sor", "radius")),
        Option("k", ("--k",), type=int, default=10, help="neighbours per point"),
        Option(
            "threshold", ("--threshold",), type=float,
            help="score threshold (default: automatic)",
        ),
        Option(
            "mask", ("--mask",), per_file=True,
            help="write the boolean keep mask to .npy: one entry per input row, in input order "
            "(True = kept; rows without coordinates, NaN in organized PCDs, are False)",
        ),
        Option(
            "scores", ("--scores",), per_file=True,
            help="write per-point outlier scores to .npy, one per input row (inf for NaN rows)",
        ),
        Option(
            "viewpoint", ("--viewpoint",), metavar="X,Y,Z",
            help="--method rpca: sensor origin of a single-view scan (0,0,0 for an organized "
            "Kinect/RGB-D frame in camera coordinates); scores are normalised by the spacing "
            "expected at each point's range, so sparse far regions are kept. Default for a PCD: "
            "its VIEWPOINT origin when organized (WIDTH x HEIGHT) or not 0 0 0 1 0 0 0; an "
            "organized PCD also uses its image grid (flying pixels removed, image-supported "
            "points kept)",
        ),
        Option(
            "device", ("--device",), default="cpu", choices=("cpu", "cuda", "auto"),
            help="where the RPCA iterations run: cpu (numba, default), cuda (PyTorch on the GPU; "
            "scores within 1e-3 spacings of cpu), auto (cuda when a GPU is visible); also for "
            "every tile with --tile. --method sor/radius and point-cloud sequences run on the CPU",
        ),
    ),
)  # fmt: skip

SALIENCY = CommandSchema(
    name="saliency",
    run=run_saliency,
    output="out",
    result=_saliency_result,
    options=(
        Option("per", ("--per",), default="vertex", choices=("vertex", "face")),
        Option("method", ("--method",), default="combined", choices=_SALIENCY_METHODS),
        Option("k", ("--k",), type=int, default=25, help="faces per patch besides the face (25)"),
        Option(
            "fast", ("--fast",), switch=True,
            help="leave the least salient class out of the RPCA",
        ),
    ),
)  # fmt: skip

COMPRESS = CommandSchema(
    name="compress",
    run=run_compress,
    output="output",
    result=_compress_result,
    options=(
        Option(
            "method", ("--method",), choices=_compress_methods,
            help="default: auto (meshes: with a target, the smaller of predictive and spectral; "
            "without one, spectral), blocks (animations)",
        ),
        Option(
            "bpv", ("--bpv",), type=float, metavar="X", group="rate",
            help="target bits per vertex",
        ),
        Option(
            "bpvf", ("--bpvf",), type=float, metavar="X", group="rate",
            help="animations: target bits per vertex per frame (whole file)",
        ),
        Option(
            "error", ("--error",), type=float, metavar="E", group="rate",
            help="target RMS vertex error as a fraction of the bounding-box diagonal; "
            "animations: KG error in percent",
        ),
        Option(
            "max_error", ("--max-error",), type=float, metavar="E", group="rate",
            help="meshes: bound on the largest vertex deviation (hence the symmetric Hausdorff "
            "distance) as a fraction of the bounding-box diagonal",
        ),
        Option(
            "step", ("--step",), type=float, group="rate",
            help="quantisation step (fraction of the diagonal) instead of a target",
        ),
        Option(
            "reorder", ("--reorder",), switch=True,
            help="let the codec renumber vertices and faces for a smaller file (meshes, and "
            "animations with --method pca-pred)",
        ),
        Option(
            "no_weld", ("--no-weld",), switch=True,
            help="meshes: code the vertices as stored; by default STL files and triangle soups "
            "are welded on reading (their corners merged), as every command reads them",
        ),
    ),
)  # fmt: skip

COMPLETE = CommandSchema(
    name="complete",
    run=run_complete,
    output="output",
    result=_geometry_result,
    options=(
        Option(
            "known", ("--known",), per_file=True,
            help="KNOWN.npy: bool mask (n,) or (T, n), or int vertex indices",
        ),
        Option(
            "method", ("--method",), choices=tuple(sorted(set(MESH_METHODS + ANIM_METHODS))),
            help="meshes: li (default) | lsm | mc, with --fill-holes lsm (default) | li | mc; "
            "animations: motion (default) | li | lia | mc",
        ),
        Option(
            "sweeps", ("--sweeps",), type=int,
            help="animations, --method motion: filtering sweeps after the satellite generations "
            "(default 20; 0 = Algorithm 12 as printed)",
        ),
        Option("fill_holes", ("--fill-holes",), switch=True, help="close every hole"),
        Option(
            "max_hole", ("--max-hole",), type=int,
            help="with --fill-holes: leave loops with more edges open",
        ),
        Option(
            "density", ("--density",), type=float,
            help="with --fill-holes: implanted points per loop edge length (default 1; lower for "
            "very large holes, whose fill grows with their area)",
        ),
    ),
)  # fmt: skip

#: The commands ``batch`` runs, by name, in help order.
COMMANDS: dict[str, CommandSchema] = {
    s.name: s for s in (DENOISE, OUTLIERS, SALIENCY, COMPRESS, COMPLETE, CONVERT)
}
