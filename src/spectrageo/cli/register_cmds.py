"""``spectrageo register``: rigid registration of a source onto a target (thesis Section 6.2).

``spectrageo register SOURCE TARGET --out T.json [--init T0.json] [--apply OUT] [--seed N]``

SOURCE and TARGET are meshes or point clouds (any readable format; meshes use their vertices).
``T.json`` holds ``transformation`` (4 rows of 4 numbers, mapping SOURCE into TARGET's frame:
``x_t = R x_s + t``), ``fitness``, ``inlier_rmse``, ``converged``, ``time_s`` (and ``n_iter``,
``inlier_distance``). ``--init`` takes such a JSON file (its ``transformation``), a JSON 4x4
list, or a whitespace-separated 4x4 text file, and skips the broad phase. ``--apply OUT`` writes
the moved SOURCE with its kind kept (mesh -> mesh with the same faces, point cloud -> point
cloud; normals are rotated). Writes are atomic.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from ._argtypes import seed_type
from ._common import check_outputs
from ._common import read_reported as _read
from ._common import status as _status


def _load_transform(path: str) -> np.ndarray:
    p = Path(path)
    if not p.is_file():
        raise InvalidInputError(f"`--init`: file not found: {path}")
    text = p.read_text(encoding="utf-8", errors="replace")
    try:
        obj = json.loads(text)
    except json.JSONDecodeError:
        try:
            obj = np.loadtxt(p, dtype=np.float64, ndmin=2).tolist()
        except ValueError as exc:
            raise InvalidInputError(
                f"`--init`: {p.name} is neither JSON nor a 4x4 text matrix ({exc})."
            ) from exc
    if isinstance(obj, dict):
        if "transformation" not in obj:
            raise InvalidInputError(f"`--init`: {p.name} has no `transformation` key.")
        obj = obj["transformation"]
    try:
        T = np.asarray(obj, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"`--init`: {p.name} must hold a 4x4 numeric matrix.") from exc
    if T.shape != (4, 4):
        raise InvalidInputError(f"`--init`: {p.name} must hold a 4x4 matrix; got shape {T.shape}.")
    return T


def _read_geometry(path: str, name: str):
    from ..geometry import Mesh, PointCloud

    if not Path(path).is_file():
        raise InvalidInputError(f"{name}: file not found: {path}")
    # rows without coordinates (NaN, as scanners write for no measurement) carry nothing to
    # align; they are left out, and the status line says how many
    obj, _ = _read(path, nan_points="drop")
    if not isinstance(obj, Mesh | PointCloud):
        raise InvalidInputError(
            f"{name}: {Path(path).name} is a {type(obj).__name__}; register needs a mesh or a "
            "point cloud."
        )
    return obj


def _check_apply_format(path: str, src) -> None:
    """Refuse an ``--apply`` file format that cannot hold the source before registering (and
    before ``--out`` is written)."""
    from ..geometry import Mesh
    from ..io._api import _MESH_WRITE, _POINTS_WRITE
    from ..io._common import split_suffix

    suffix = split_suffix(Path(path))[0]
    allowed = _MESH_WRITE if isinstance(src, Mesh) else _POINTS_WRITE
    if suffix not in allowed:
        kind = "mesh" if isinstance(src, Mesh) else "point cloud"
        raise InvalidInputError(
            f"--apply: cannot write the moved {kind} as {suffix or '(no extension)'!r}; "
            f"use one of {', '.join(allowed)}."
        )


def _moved(obj, T: np.ndarray):
    """``obj`` (Mesh or PointCloud) moved by ``T``, same kind, normals rotated."""
    from ..geometry import Mesh
    from ..register._common import apply_transform

    R = T[:3, :3]
    if isinstance(obj, Mesh):
        N = obj.vertex_normals
        return dataclasses.replace(
            obj,
            vertices=apply_transform(T, obj.vertices),
            vertex_normals=None if N is None else np.asarray(N) @ R.T,
        )
    N = obj.normals
    return dataclasses.replace(
        obj,
        points=apply_transform(T, obj.points),
        normals=None if N is None else np.asarray(N) @ R.T,
    )


def _json_text(report: dict) -> str:
    """JSON with the transformation written one row per line."""
    rows = ",\n".join("    " + json.dumps(r) for r in report["transformation"])
    rest = "".join(
        f',\n  "{k}": {json.dumps(v)}' for k, v in report.items() if k != "transformation"
    )
    return '{\n  "transformation": [\n' + rows + "\n  ]" + rest + "\n}\n"


def cmd_register(args) -> int:
    from .. import io
    from ..io import atomic_write
    from ..register import register

    check_outputs([args.source, args.target], [args.out, args.apply])
    init = _load_transform(args.init) if args.init else None
    t0 = time.perf_counter()
    src = _read_geometry(args.source, "SOURCE")
    if args.apply:
        _check_apply_format(args.apply, src)
    tgt = _read_geometry(args.target, "TARGET")
    res = register(src, tgt, init=init, rng=args.seed)
    elapsed = time.perf_counter() - t0
    T = res.transformation
    report = {
        "transformation": [[float(x) for x in row] for row in T],
        "fitness": float(res.fitness),
        "inlier_rmse": float(res.inlier_rmse) if np.isfinite(res.inlier_rmse) else None,
        "converged": bool(res.converged),
        "time_s": float(elapsed),
        "n_iter": int(res.n_iter),
        "inlier_distance": float(res.inlier_distance),
    }
    out = Path(args.out)
    with atomic_write(out) as tmp:
        Path(tmp).write_text(_json_text(report), encoding="utf-8")
    if args.apply:
        io.write(args.apply, _moved(src, T))
    _status(
        f"wrote {args.out}: fitness {res.fitness:.3f}, inlier rmse {res.inlier_rmse:.3g}, "
        f"{'converged' if res.converged else 'not converged'} ({elapsed:.2f} s)"
        + (f"; moved source in {args.apply}" if args.apply else "")
    )
    return 0


def register(sub) -> None:
    """Add ``register`` to the ``spectrageo`` sub-parsers."""
    p = sub.add_parser(
        "register", help="rigid registration of a source onto a target (broad + narrow, Sec. 6.2)"
    )
    p.add_argument("source", help="mesh or point cloud to move")
    p.add_argument("target", help="mesh or point cloud that stays")
    p.add_argument(
        "--out",
        required=True,
        help="T.json: transformation, fitness, inlier_rmse, converged, n_iter, time_s",
    )
    p.add_argument(
        "--init",
        default=None,
        help="T0.json (or 4x4 text) initial transform; skips the broad phase",
    )
    p.add_argument("--apply", default=None, help="OUT: write the moved source (same kind)")
    p.add_argument("--seed", type=seed_type, default=0, help="seed of the broad phase (default 0)")
    p.set_defaults(func=cmd_register)
    p.description = (
        "Register SOURCE onto TARGET: broad phase (global, from local shape properties and a\n"
        "density peak in transformation space), robustification (outlier and boundary removal)\n"
        "and narrow phase (Tukey-weighted ICP). The transformation maps SOURCE into TARGET's frame."
    )
    p.epilog = (
        "example:\n  spectrageo register scan1.ply scan0.ply --out T.json --apply scan1_aligned.ply\n"
        "  spectrageo register part.pcd model.obj --out T.json --init T0.json"
    )


__all__ = ["register"]
