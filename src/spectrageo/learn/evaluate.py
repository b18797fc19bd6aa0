"""Evaluation of the learned denoisers against TSGSP and BNF, on data no weight was trained on.

Parts: the pairs of ``denoise/``; a slice of the protocol's validation split at Gaussian noise 0.3
and 0.5; the shared animations at 0.3, ``dae`` trained on their first frames. Every method runs
through :func:`spectrageo.denoise.denoise`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .._progress import progress
from ..datasets.splits import cases as _cases
from ..datasets.splits import split_of

STATIC_METHODS = ("bm3d-cnn", "dae", "tsgsp", "bnf")
#: validation-split slice: organic and CAD meshes of 6k-26k vertices (the split registry's
#: ``learn`` task, :mod:`spectrageo.datasets.splits`)
VALIDATION_SLICE = tuple(c.file for c in _cases("learn", "validation") if c.group != "animation")
LEVELS = (0.3, 0.5)
ANIMATIONS = tuple(c.name for c in _cases("learn", group="animation"))
COLUMNS = ("part", "case", "method", "n_vertices", "input_theta", "theta_deg", "time_s", "split")


def _theta(X, V0, F) -> float:
    from ..metrics import theta_deg

    return float(theta_deg(X, V0, F))


def _static_rows(part, case, Vn, V0, F, methods, rows, repeat=1, split="-"):
    from .. import denoise

    th0 = _theta(Vn, V0, F)
    for m in methods:
        dt = np.inf
        for _ in range(max(1, int(repeat))):  # deterministic output: keep the best time
            t = time.perf_counter()
            X = denoise.denoise(Vn, F, method=m)
            dt = min(dt, time.perf_counter() - t)
        rows.append(
            {"part": part, "case": case, "method": m, "n_vertices": int(Vn.shape[0]),
             "input_theta": th0, "theta_deg": _theta(X, V0, F), "time_s": dt, "split": split}
        )  # fmt: skip


def evaluate_learned(
    data=None,
    out=None,
    *,
    methods=STATIC_METHODS,
    validation=VALIDATION_SLICE,
    levels=LEVELS,
    animations=ANIMATIONS,
    max_frames: int = 12,
    train_frames: int = 8,
    frame_step: int = 3,
    repeat: int = 1,
    protocol_levels=(),
    protocol_max_vertices: int = 30000,
) -> list[dict]:
    """Run the comparison of the module notes; returns the rows (:data:`COLUMNS`), written with ``out``.

    ``repeat``: best time of that many runs; ``frame_step``: animation frames evaluated;
    ``protocol_levels``: also the protocol's validation split at those levels (models up to
    ``protocol_max_vertices``).
    """
    from .. import denoise, io
    from ..datasets import data_dir as _data_dir
    from ..datasets import denoise_pairs
    from ..evaluate.denoise import ProtocolCase, _load_clean
    from ..noise import animation_noise, generate
    from ..noise.generator import case_seed
    from .dae import dae_animation

    data = _data_dir(required=True) if data is None else Path(data)
    rows: list[dict] = []
    from ..denoise._registry import warm_up

    warm_up(list(methods), *_warm_mesh())
    for name, npth, opth in progress(denoise_pairs(data), desc="pairs"):
        n, o = io.read_mesh(npth), io.read_mesh(opth)
        split = split_of("denoise", name) or "-"
        _static_rows("pairs", name, n.vertices, o.vertices, o.faces, methods, rows, repeat, split)
    for rel in progress(validation, desc="validation"):
        for lv in levels:
            case = ProtocolCase(
                "validation",
                rel,
                "gaussian-normal",
                lv,
                case_seed(rel, "gaussian-normal", lv, seed=0),
            )
            _, V0, F = _load_clean(data, case)
            Vn = generate(V0, F, kind="gaussian-normal", level=lv, rng=case.seed).vertices
            split = split_of("learn", rel) or "-"
            _static_rows("validation", case.name, Vn, V0, F, methods, rows, repeat, split)
    if protocol_levels:
        from ..evaluate.denoise import protocol_cases

        for case in progress(protocol_cases("validation", levels=protocol_levels), desc="protocol"):
            _, V0, F = _load_clean(data, case)
            if V0.shape[0] > int(protocol_max_vertices):
                continue
            Vn = generate(V0, F, kind=case.corruption, level=case.level, rng=case.seed).vertices
            # one timed run
            _static_rows("protocol", case.name, Vn, V0, F, methods, rows, split=case.split)
    for name in progress(animations, desc="animations"):
        path = data / "animations" / f"{name}.npz"
        if not path.is_file():
            continue
        z = np.load(path)
        A = np.asarray(z["vertices"][:max_frames], dtype=np.float64)
        F = np.asarray(z["faces"], dtype=np.int64)
        An = animation_noise(A, F, kind="gaussian", level=0.3, rng=0)
        ev = list(range(0, A.shape[0], frame_step))
        case = f"{name}[{A.shape[0]} frames]:gaussian@0.3"
        base = {"part": "animation", "case": case, "n_vertices": int(A.shape[1]),
                "split": split_of("learn", name) or "-"}  # fmt: skip
        th0 = float(np.mean([_theta(An[t], A[t], F) for t in ev]))
        t = time.perf_counter()
        D = dae_animation(An, F, train_frames=min(train_frames, A.shape[0]))
        dt = time.perf_counter() - t
        rows.append(base | {"method": f"dae (train {train_frames} frames)", "input_theta": th0,
                            "theta_deg": float(np.mean([_theta(D[t], A[t], F) for t in ev])),
                            "time_s": dt * len(ev) / A.shape[0]})  # fmt: skip
        t = time.perf_counter()
        th = [_theta(denoise.denoise(An[t], F, method="tsgsp"), A[t], F) for t in ev]
        rows.append(base | {"method": "tsgsp (per frame)", "input_theta": th0,
                            "theta_deg": float(np.mean(th)), "time_s": time.perf_counter() - t})  # fmt: skip
    if out is not None:
        write(rows, out)
    return rows


def _warm_mesh():
    from ..datasets import fandisk

    m = fandisk()
    return m.vertices, m.faces


def summary(rows: list[dict]) -> list[dict]:
    """Mean theta and time per part and method (animations: over the shared animations)."""
    out = []
    keys = []
    for r in rows:
        k = (r["part"], r["method"])
        if k not in keys:
            keys.append(k)
    for part, m in keys:
        sel = [r for r in rows if r["part"] == part and r["method"] == m]
        out.append(
            {"part": part, "method": m, "cases": len(sel),
             "input_theta": float(np.mean([r["input_theta"] for r in sel])),
             "theta_deg": float(np.mean([r["theta_deg"] for r in sel])),
             "time_s": float(np.mean([r["time_s"] for r in sel]))}
        )  # fmt: skip
    return out


def format_markdown(rows: list[dict], note: str = "") -> str:
    from ..evaluate._tables import markdown_table

    lines = ["## Learned denoisers (Sections 5.1.3-5.1.4) against TSGSP and BNF", ""]
    if note:
        lines += [note, ""]
    lines += ["Mean theta (degrees) and mean seconds per case.", ""]
    lines += markdown_table(
        summary(rows), ("part", "method", "cases", "input_theta", "theta_deg", "time_s")
    )
    lines += _time_ratio_lines(rows)
    lines += _versus_lines(rows)
    lines += ["", "### Per case", ""]
    lines += markdown_table(rows, COLUMNS)
    return "\n".join(lines) + "\n"


def time_ratios(rows: list[dict], lo: int = 10_000, hi: int = 100_000) -> dict[str, list[float]]:
    """Per learned method, its time over TSGSP's on every static case with ``lo``-``hi``
    vertices (the range of issue 20's speed target), outside the ``"protocol"`` part (timed
    once per case there)."""
    out: dict[str, list[float]] = {}
    static = [
        r
        for r in rows
        if r["part"] not in ("animation", "protocol") and lo <= r["n_vertices"] <= hi
    ]
    for r in static:
        if r["method"] in ("tsgsp", "bnf"):
            continue
        ref = [q for q in static if q["case"] == r["case"] and q["method"] == "tsgsp"]
        if ref:
            out.setdefault(r["method"], []).append(r["time_s"] / ref[0]["time_s"])
    return out


def versus_tsgsp(rows: list[dict]) -> dict[tuple[str, str], dict[str, int]]:
    """Per (part, learned method): cases, cases below TSGSP's theta, cases above the noisy
    input (static parts)."""
    out: dict[tuple[str, str], dict[str, int]] = {}
    static = [r for r in rows if r["part"] != "animation"]
    ref = {(r["part"], r["case"]): r for r in static if r["method"] == "tsgsp"}
    for r in static:
        t = ref.get((r["part"], r["case"]))
        if r["method"] in ("tsgsp", "bnf") or t is None:
            continue
        c = out.setdefault(
            (r["part"], r["method"]), {"cases": 0, "below_tsgsp": 0, "above_input": 0}
        )
        c["cases"] += 1
        c["below_tsgsp"] += int(r["theta_deg"] < t["theta_deg"])
        c["above_input"] += int(r["theta_deg"] > r["input_theta"])
    return out


def _versus_lines(rows: list[dict]) -> list[str]:
    v = versus_tsgsp(rows)
    if not v:
        return []
    parts = [
        f"{part} `{m}`: {c['below_tsgsp']} of {c['cases']} (above the noisy input on "
        f"{c['above_input']})"
        for (part, m), c in v.items()
    ]
    return ["", "Cases where a learned method ends below TSGSP's theta: " + "; ".join(parts) + "."]


def _time_ratio_lines(rows: list[dict]) -> list[str]:
    ratios = time_ratios(rows)
    if not ratios:
        return []
    parts = [
        f"`{m}` median {np.median(v):.2f}, largest {max(v):.2f} ({len(v)} cases)"
        for m, v in ratios.items()
    ]
    return ["", "Time relative to TSGSP on the static cases of 10k-100k vertices: "
            + "; ".join(parts) + "."]  # fmt: skip


def write(rows: list[dict], out, note: str = ""):
    """``<out>.md`` and ``<out>.csv`` (atomic); returns both paths."""
    from ..evaluate._tables import rows_to_csv, write_md_csv

    return write_md_csv(out, format_markdown(rows, note), rows_to_csv(rows, COLUMNS))


__all__ = [
    "ANIMATIONS",
    "COLUMNS",
    "VALIDATION_SLICE",
    "evaluate_learned",
    "format_markdown",
    "summary",
    "time_ratios",
    "versus_tsgsp",
]
