"""Evaluation of mesh-animation denoising on the shared animations (Section 5.1.2, Figs. 5.26-5.28).

Every animation of ``<data>/animations`` (crane, horse-gallop, horse-collapse, chickenCrossing) is
corrupted with Gaussian noise (level 0.2 of the mean edge length along the normals, Table 5.6),
impulsive noise (10 % of the vertices of every frame) and uniform noise, then denoised by the
dynamic methods (``gft-rpca``, ``normals-rpca``) and by the static methods run frame by frame
(``bnf``, ``gnf``, ``tsgsp``). Reported per run: mean theta over the frames (degrees), mean one-sided
Hausdorff distance (result vertices to the reference surface, averaged over the evaluated frames),
KG error (percent), STED and the wall time of the denoiser.

Used by ``spectrageo evaluate denoise-dynamic [--methods ...] [--out FILE]``.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._progress import progress
from ..datasets.splits import cases as _cases
from ..datasets.splits import split_of
from ._tables import rows_to_csv, write_md_csv

#: the animations of the split registry's ``denoise-dynamic`` task (:mod:`spectrageo.datasets.splits`)
ANIMATIONS = tuple(c.name for c in _cases("denoise-dynamic"))
DEFAULT_METHODS = ("gft-rpca", "normals-rpca", "bnf", "gnf", "tsgsp")
#: (kind, level) of the corruptions.
NOISES = (("gaussian", 0.2), ("impulsive", 0.5), ("uniform", 0.2))
COLUMNS = (
    "animation",
    "n_vertices",
    "n_frames",
    "noise",
    "method",
    "theta_deg",
    "hd_mean",
    "kg",
    "sted",
    "seconds",
    "note",
    "split",
)


def _load(data_dir: Path, name: str, max_frames: int | None):
    from ..io import read_animation

    path = data_dir / "animations" / f"{name}.npz"
    if not path.is_file():
        return None
    anim = read_animation(path)
    A = np.asarray(anim.frames, dtype=np.float64)
    if max_frames is not None:
        A = A[:max_frames]
    return A, np.asarray(anim.faces, dtype=np.int64)


def _metrics(X: np.ndarray, A: np.ndarray, F: np.ndarray, hd_frames: int) -> dict:
    from ..metrics import hausdorff, kg_error, sted, theta_per_frame

    T = A.shape[0]
    idx = np.unique(np.linspace(0, T - 1, min(T, hd_frames)).round().astype(int))
    hd = [hausdorff(X[t], None, A[t], F, symmetric=False).hd_mean for t in idx]
    return {
        "theta_deg": float(np.mean(theta_per_frame(X, A, F))),
        "hd_mean": float(np.mean(hd)),
        "kg": float(kg_error(X, A)),
        "sted": float(sted(X, A, F)),
    }


def evaluate(
    data_dir: Any,
    methods: list[str] | None = None,
    out: Any = None,
    *,
    animations: tuple[str, ...] | list[str] | None = None,
    noises: tuple[tuple[str, float], ...] | None = None,
    max_frames: int | None = None,
    hd_frames: int = 10,
    rng: int = 0,
) -> list[dict]:
    """Run the animation denoisers on the shared animations; returns one row per run.

    Parameters
    ----------
    data_dir : path
        Shared data folder (holding ``animations/*.npz``).
    methods : list of str, optional
        Default ``gft-rpca, normals-rpca, bnf, gnf, tsgsp``; names that are neither dynamic methods
        nor registered static denoisers give a row with ``note="unavailable"``.
    out : path, optional
        Write ``<out>.md`` and ``<out>.csv`` (atomically).
    animations : names, optional
        Subset of :data:`ANIMATIONS` (missing files are skipped).
    noises : ((kind, level), ...), optional
        Default :data:`NOISES`.
    max_frames : int, optional
        Use only the first ``max_frames`` frames of every animation (all by default).
    hd_frames : int
        Number of evenly spaced frames on which the Hausdorff distance is averaged.
    rng : int
        Seed of the noise (the same noisy animation for every method).

    Returns
    -------
    list of dict with the keys of :data:`COLUMNS` (a ``"noisy"`` row per animation and noise;
    ``split`` from the split registry).
    """
    from .. import denoise as dn
    from ..noise import animation_noise

    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise InvalidInputError(f"`data_dir` must be a folder; got {data_dir}.")
    methods = list(DEFAULT_METHODS if methods is None else methods)
    if not methods or not all(isinstance(m, str) and m for m in methods):
        raise InvalidInputError(f"`methods` must be a non-empty list of names; got {methods!r}.")
    names = tuple(ANIMATIONS if animations is None else animations)
    bad = [a for a in names if a not in ANIMATIONS]
    if bad:
        raise InvalidInputError(
            f"unknown animation(s) {', '.join(bad)}; known: {', '.join(ANIMATIONS)}."
        )
    noises = tuple(NOISES if noises is None else noises)
    if max_frames is not None and (
        isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 2
    ):
        raise InvalidInputError(
            f"`max_frames` must be an integer >= 2 or None; got {max_frames!r}."
        )
    dynamic = set(dn.dynamic_methods())
    static = set(dn.available())
    rows: list[dict] = []
    for name in progress(names, desc="animations", total=len(names)):
        loaded = _load(data_dir, name, max_frames)
        if loaded is None:
            continue
        A, F = loaded
        T, n, _ = A.shape
        for kind, level in noises:
            noisy = animation_noise(A, F, kind=kind, level=level, rng=rng)
            base = {"animation": name, "n_vertices": n, "n_frames": T, "noise": f"{kind} {level:g}",
                    "split": split_of("denoise-dynamic", name) or "-"}  # fmt: skip
            rows.append({**base, "method": "noisy", **_metrics(noisy, A, F, hd_frames),
                         "seconds": 0.0, "note": ""})  # fmt: skip
            for m in methods:
                row = {**base, "method": m}
                if m not in dynamic and m not in static:
                    rows.append({**row, "theta_deg": np.nan, "hd_mean": np.nan, "kg": np.nan,
                                 "sted": np.nan, "seconds": np.nan, "note": "unavailable"})  # fmt: skip
                    continue
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    X = dn.denoise_animation(noisy, F, method=m)
                sec = time.perf_counter() - t0
                rows.append({**row, **_metrics(X, A, F, hd_frames), "seconds": sec,
                             "note": "dynamic" if m in dynamic else "per frame"})  # fmt: skip
    if out is not None:
        write_tables(rows, out)
    return rows


def _fmt(key: str, v) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if v is None or not np.isfinite(v):
        return "-"
    if key == "hd_mean":
        return f"{v:.3e}"
    if key == "seconds":
        return f"{v:.1f}"
    return f"{v:.4g}"


def format_markdown(rows: list[dict]) -> str:
    """Markdown table of :func:`evaluate` rows (the best theta of every animation/noise in bold)."""
    head = "| animation | n | T | noise | method | theta (deg) | HD mean | KG (%) | STED | time (s) | note | split |"
    lines = [head, "|" + "---|" * len(COLUMNS)]
    best: dict[tuple, float] = {}
    for r in rows:
        if r["method"] != "noisy" and np.isfinite(r["theta_deg"]):
            key = (r["animation"], r["noise"])
            best[key] = min(best.get(key, np.inf), r["theta_deg"])
    for r in rows:
        cells = [_fmt(k, r.get(k, "-")) for k in COLUMNS]
        if r["method"] != "noisy" and r["theta_deg"] == best.get((r["animation"], r["noise"])):
            cells[5] = f"**{cells[5]}**"
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def format_csv(rows: list[dict]) -> str:
    """CSV text of the rows (full precision)."""
    return rows_to_csv(rows, COLUMNS)


def write_tables(rows: list[dict], out) -> tuple[Path, Path]:
    """Write ``<out>.md`` and ``<out>.csv`` atomically; returns both paths."""
    return write_md_csv(
        out,
        "## Mesh animation denoising\n\n"
        "Produced by `spectrageo evaluate denoise-dynamic`; every method with its default "
        "settings, static methods run frame by frame.\n\n" + format_markdown(rows) + "\n",
        format_csv(rows),
    )


__all__ = ["ANIMATIONS", "COLUMNS", "DEFAULT_METHODS", "NOISES", "evaluate", "format_csv",
           "format_markdown", "write_tables"]  # fmt: skip
