"""Evaluation of identification in cluttered scans (thesis Section 6.2.8, Tables 6.6, 6.8-6.9,
Fig. 6.40): ``spectrageo evaluate identify``.

Parts: ``scene``, scans from :func:`spectrageo.register.make_scene` (3-6 of the 10 models of
:data:`LIBRARY`, clutter, 640 x 480 pixels), every model searched in every scene with
:func:`spectrageo.register.identify`; ``milk``, the PCL Kinect scene with its model as given and
moved by a known motion; ``dbscan``, :func:`spectrageo.register.adaptive_dbscan` against
scikit-learn's ``DBSCAN`` at one global ``eps`` (the 90th percentile of the adaptive radii).

Tables (:func:`format_markdown`): TP/TN/FP/FN, specificity, precision, recall, accuracy, FPR and
F1 per model (Tables 6.8-6.9); the recognition rate per occlusion bin (Fig. 6.40; rotation below
10 degrees, translation below 5 % of the diagonal); times; the milk and DBSCAN results.

Split (:mod:`spectrageo.datasets.splits`, task ``identify``): :data:`TUNING` scenes 1-10 and
31-50 chose the defaults that are not the thesis's; :data:`VALIDATION` is 11-18, consulted for
two rules (docs/decisions.md#identify-validation-consulted). By default the tuning scenes
:data:`REPORTED_TUNING` and every validation scene run; ``seeds`` of :func:`evaluate`, or the
environment variable ``SPECTRAGEO_IDENTIFY_SEEDS`` (``1-10,31-50`` or ``all``), chooses others.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from ..datasets.splits import IDENTIFY_LIBRARY, split_of
from ..datasets.splits import cases as _cases
from ._tables import fmt_cell, have, pyplot, rows_to_csv, save_png, write_section

#: the model library of the scenes (name -> path), from the split registry
LIBRARY = dict(IDENTIFY_LIBRARY)


def _seeds(split: str) -> tuple[int, ...]:
    return tuple(c.seed for c in _cases("identify", split) if c.file is None)


def parse_seeds(text: str) -> tuple[int, ...]:
    """Seeds of a list of ranges such as ``"1-3,11-18"``.

    Raises
    ------
    InvalidInputError
        When ``text`` is not comma-separated integers or ``a-b`` ranges.
    """
    out: list[int] = []
    for part in str(text).split(","):
        a, _, b = part.strip().partition("-")
        try:
            lo, hi = int(a), int(b or a)
        except ValueError:
            raise InvalidInputError(f"seeds must read like '1-3,11-18'; got {text!r}.") from None
        out += range(lo, hi + 1)
    return tuple(out)


#: the scene seeds of the split registry's ``identify`` task (:mod:`spectrageo.datasets.splits`)
TUNING = {"seeds": _seeds("tuning")}
VALIDATION = {"seeds": _seeds("validation")}
#: the tuning scenes of a default run (all 30 take about 30 times one scene's 20-60 s)
REPORTED_TUNING = (1, 2, 3)
OCCLUSION_BINS = (0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
ROT_OK_DEG = 10.0
TRANS_OK = 0.05
COLUMNS = ("part", "split", "scene", "model", "present", "found", "h", "occlusion",
           "rot_err_deg", "trans_err", "recognized", "n_points", "n_clusters", "ari",
           "seconds", "method", "note")  # fmt: skip
METHODS = ("identify",)


def load_library(data: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The library meshes, centred and scaled to a unit bounding-box diagonal."""
    from .. import io

    lib = {}
    for name, rel in LIBRARY.items():
        p = data / rel
        if not p.is_file():
            continue
        m = io.read_mesh(p)
        V = np.asarray(m.vertices, dtype=np.float64)
        V = (V - 0.5 * (V.min(0) + V.max(0))) / np.linalg.norm(np.ptp(V, axis=0))
        lib[name] = (V, np.asarray(m.faces, dtype=np.int64))
    return lib


def pose_errors(match, scene) -> dict:
    """``occlusion``, ``rot_err_deg``, ``trans_err`` (model diagonals) and ``recognized`` of the
    :class:`~spectrageo.register.Match` of a model present in a generated ``scene``."""
    from ..metrics.registration import rotation_error_deg, translation_error

    j = scene.names.index(match.model)
    T, Tg = match.transformation, scene.poses[j]
    re = rotation_error_deg(T[:3, :3], Tg[:3, :3])
    # translation of the model's centre (the library models are centred)
    te = translation_error(T[:3, 3], Tg[:3, 3])
    return {"occlusion": float(scene.occlusion[j]), "rot_err_deg": re, "trans_err": te,
            "recognized": bool(match.found and re <= ROT_OK_DEG and te <= TRANS_OK)}  # fmt: skip


def _scenes(lib, split: str, seeds, progress) -> list[dict]:
    from ..register import identify, make_scene

    rows = []
    for seed in seeds:
        sc = make_scene(lib, n_objects=3 + seed % 4, rng=seed)
        t0 = time.perf_counter()
        # the generated scans know their sensor position: free-space verification applies
        res = identify(sc.points, lib, rng=0, viewpoint=sc.viewpoint)
        sec = time.perf_counter() - t0
        progress(f"{split} scene {seed}: {len(sc.points)} points, {sec:.1f} s")
        for m in res:
            present = m.model in sc.names
            row = {"part": "scene", "split": split, "scene": seed, "model": m.model,
                   "present": present, "found": m.found, "h": m.dissimilarity,
                   "n_points": int(len(sc.points)), "seconds": sec, "method": "identify"}  # fmt: skip
            if present:
                row.update(pose_errors(m, sc))
            rows.append(row)
    return rows


def _milk(data: Path) -> list[dict]:
    from .. import io
    from ..metrics.registration import rotation_error_deg, translation_error
    from ..register import identify
    from ..register.scenes import random_rotation

    d = data / "scans" / "pcl"
    sp, mp = d / "milk_cartoon_all_small_clorox.pcd", d / "milk.pcd"
    if not (sp.is_file() and mp.is_file()):
        return []
    S = io.read(sp).points
    M = io.read(mp).points
    diag = float(np.linalg.norm(np.ptp(M, axis=0)))
    R = random_rotation(np.random.default_rng(7))
    t = np.array([0.3, -0.2, 0.4])
    cases = [("milk.pcd as given", M, np.eye(4)),
             ("milk.pcd moved", M @ R.T + t, np.r_[np.c_[R.T, -R.T @ t], [[0, 0, 0, 1]]])]  # fmt: skip
    rows = []
    for note, Mi, Tg in cases:
        t0 = time.perf_counter()
        m = identify(S, {"milk": Mi}, rng=0)[0]
        sec = time.perf_counter() - t0
        re = rotation_error_deg(m.transformation[:3, :3], Tg[:3, :3])
        te = translation_error(m.transformation[:3, 3], Tg[:3, 3]) / diag
        rows.append({"part": "milk", "split": split_of("identify", "milk") or "-",
                     "scene": "milk_cartoon_all_small_clorox",
                     "model": "milk", "present": True, "found": m.found, "h": m.dissimilarity,
                     "rot_err_deg": re, "trans_err": te,
                     "recognized": bool(m.found and re <= ROT_OK_DEG and te <= TRANS_OK),
                     "n_points": int(S.shape[0]), "seconds": sec, "method": "identify",
                     "note": f"{note}; segment {m.n_points} points"})  # fmt: skip
    return rows


def _dbscan(data: Path, lib, seeds) -> list[dict]:
    from sklearn.cluster import DBSCAN
    from sklearn.metrics import adjusted_rand_score

    from .. import io
    from ..register import adaptive_dbscan, make_scene
    from ..register._segment import adaptive_eps, remove_planes

    clouds = []
    for seed in seeds:
        sc = make_scene(lib, n_objects=3 + seed % 4, rng=seed)
        split = split_of("identify", f"scene {seed}", seed=seed) or "-"
        clouds.append((f"generated {seed}", sc.points, 0.5 * sc.pixel_size, split))
    p = data / "scans" / "pcl" / "milk_cartoon_all_small_clorox.pcd"
    if p.is_file():
        split = split_of("identify", "milk") or "-"
        clouds.append(("milk_cartoon_all_small_clorox", io.read(p).points, 0.01, split))
    rows = []
    for name, P, thr, split in clouds:
        keep, _ = remove_planes(P, threshold=max(thr, 1e-9) * 2, rng=0)
        Q = P[keep]
        t0 = time.perf_counter()
        a = adaptive_dbscan(Q, workers=1)
        ta = time.perf_counter() - t0
        eps = float(np.percentile(adaptive_eps(Q, workers=1), 90))
        t0 = time.perf_counter()
        b = DBSCAN(eps=eps, min_samples=5, n_jobs=1).fit_predict(Q)
        tb = time.perf_counter() - t0

        def n_big(lab):
            cnt = np.bincount(lab[lab >= 0]) if (lab >= 0).any() else np.zeros(0)
            return int((cnt >= 50).sum())

        # the exhaustive O(n^2) neighbour search of the "original DBSCAN" of Table 6.6
        t0 = time.perf_counter()
        c = DBSCAN(eps=eps, min_samples=5, algorithm="brute", n_jobs=1).fit_predict(Q)
        tc = time.perf_counter() - t0
        ari = float(adjusted_rand_score(a, b))
        common = {"part": "dbscan", "split": split, "scene": name, "n_points": int(Q.shape[0]),
                  "ari": ari}  # fmt: skip
        rows.append({**common, "method": "adaptive (ours)", "n_clusters": n_big(a), "seconds": ta})
        rows.append({**common, "method": "sklearn DBSCAN", "n_clusters": n_big(b), "seconds": tb,
                     "note": f"eps={eps:.4g}; speed-up x{tb / max(ta, 1e-9):.1f}"})  # fmt: skip
        rows.append({**common, "method": "sklearn DBSCAN brute", "n_clusters": n_big(c),
                     "seconds": tc, "ari": float(adjusted_rand_score(a, c)),
                     "note": f"eps={eps:.4g}; speed-up x{tc / max(ta, 1e-9):.1f}"})  # fmt: skip
    return rows


def evaluate(
    data_dir: Any,
    methods: list[str] | None = None,
    out: Any = None,
    *,
    n_validation: int | None = None,
    parts: tuple[str, ...] = ("scene", "milk", "dbscan"),
    progress=None,
    seeds=None,
) -> list[dict]:
    """Run the identification benchmark; one row per (scene, model), milk case and DBSCAN run.

    ``methods`` may only name ``identify`` (the one method; peers do not identify models).
    ``n_validation`` limits the validation scenes (default: all of :data:`VALIDATION`).
    ``seeds`` (a sequence, a string ``"1-10,31-50"`` or ``"all"``; default
    ``$SPECTRAGEO_IDENTIFY_SEEDS``, else :data:`REPORTED_TUNING` and all of :data:`VALIDATION`)
    keeps only those registered scenes; a seed the registry lacks raises InvalidInputError.
    """
    data = Path(data_dir)
    if not data.is_dir():
        raise InvalidInputError(f"`data_dir` must be a folder; got {data}.")
    if methods and set(methods) - set(METHODS):
        raise InvalidInputError(
            f"unknown method(s) {', '.join(sorted(set(methods) - set(METHODS)))}; known: identify."
        )
    import sys

    def _p(msg):
        if progress is None:
            print(msg, file=sys.stderr, flush=True)
        elif progress:
            progress(msg)

    if seeds is None:
        seeds = os.environ.get("SPECTRAGEO_IDENTIFY_SEEDS") or None
    if seeds is None:
        seeds = (*REPORTED_TUNING, *VALIDATION["seeds"])
    sel = parse_seeds(seeds) if isinstance(seeds, str) and seeds != "all" else seeds
    tseeds, vseeds = TUNING["seeds"], VALIDATION["seeds"]
    if sel != "all":
        unknown = sorted(set(sel) - set(tseeds) - set(vseeds))
        if unknown:
            raise InvalidInputError(f"scene seeds {unknown} are not in the split registry.")
        tseeds = tuple(s for s in tseeds if s in sel)
        vseeds = tuple(s for s in vseeds if s in sel)
    lib = load_library(data)
    rows: list[dict] = []
    vseeds = vseeds[: n_validation if n_validation is not None else None]
    if "scene" in parts and lib:
        rows += _scenes(lib, "tuning", tseeds, _p)
        rows += _scenes(lib, "validation", vseeds, _p)
    if "milk" in parts:
        rows += _milk(data)
    if "dbscan" in parts and lib:
        rows += _dbscan(data, lib, VALIDATION["seeds"][:2])
    if out is not None:
        write_tables(rows, out)
    return rows


def _stats(rr: list[dict]) -> dict:
    tp = sum(r["present"] and r["found"] for r in rr)
    fp = sum((not r["present"]) and r["found"] for r in rr)
    fn = sum(r["present"] and not r["found"] for r in rr)
    tn = sum((not r["present"]) and not r["found"] for r in rr)

    def div(a, b):
        return a / b if b else float("nan")

    prec, rec = div(tp, tp + fp), div(tp, tp + fn)
    return {"TP": f"{tp}/({tp + fn})", "TN": f"{tn}/({tn + fp})", "FP": fp, "FN": fn,
            "Spec.": div(tn, tn + fp), "Prec.": prec, "Recall": rec,
            "Acc.": div(tp + tn, len(rr)), "FPR": div(fp, fp + tn),
            "F1": (float("nan") if tp + fp + fn == 0 else div(2 * tp, 2 * tp + fp + fn))}  # fmt: skip


def recognition_by_occlusion(rows: list[dict]) -> list[tuple[str, int, float]]:
    """``(bin label, n present, recognition rate)`` per occlusion bin of the present objects."""
    rr = [r for r in rows if r.get("part") == "scene" and r.get("present")]
    out = []
    b = (0.0, *OCCLUSION_BINS)
    for lo, hi in zip(b[:-1], b[1:]):
        sel = [r for r in rr if lo <= r["occlusion"] < hi or (hi == 1.0 and r["occlusion"] == 1)]
        if sel:
            out.append((f"{lo:.1f}-{hi:.1f}", len(sel), float(np.mean([r["recognized"] for r in sel]))))  # fmt: skip
    return out


def format_markdown(rows: list[dict]) -> str:
    """Tables 6.8-6.9 (per split), recognition vs occlusion, times, milk, DBSCAN speed."""
    lines: list[str] = []
    sc = [r for r in rows if r.get("part") == "scene"]
    keys = ("TP", "TN", "FP", "FN", "Spec.", "Prec.", "Recall", "Acc.", "FPR", "F1")
    for split in ("tuning", "validation"):
        rr = [r for r in sc if r["split"] == split]
        if not rr:
            continue
        n_sc = len({r["scene"] for r in rr})
        lines += [f"### Identification, {split} split ({n_sc} scenes; Tables 6.8-6.9 form)", "",
                  "| model | " + " | ".join(keys) + " |", "|---" * (len(keys) + 1) + "|"]  # fmt: skip
        for name in dict.fromkeys(r["model"] for r in rr):
            st = _stats([r for r in rr if r["model"] == name])
            lines.append(f"| {name} | " + " | ".join(fmt_cell(st[k]) for k in keys) + " |")
        st = _stats(rr)
        lines.append("| **Total** | " + " | ".join(f"**{fmt_cell(st[k])}**" for k in keys) + " |")
        pres = [r for r in rr if r["present"] and r["found"]]
        if pres:
            re = np.array([r["rot_err_deg"] for r in pres])
            te = np.array([r["trans_err"] for r in pres])
            lines += ["", f"Pose of the found present models: median rotation error "
                      f"{np.median(re):.2f} deg, median translation error {np.median(te):.4f} "
                      f"diagonals; {int(np.sum((re <= ROT_OK_DEG) & (te <= TRANS_OK)))}/{len(pres)}"
                      f" within {ROT_OK_DEG:g} deg and {TRANS_OK:g} diagonals."]  # fmt: skip
        secs = sorted({(r["scene"], r["seconds"]) for r in rr})
        lines += [f"Time per scene (all {len({r['model'] for r in rr})} models searched): "
                  f"mean {np.mean([s for _, s in secs]):.1f} s, max {np.max([s for _, s in secs]):.1f} s "
                  f"({int(np.mean([r['n_points'] for r in rr]))} points on average).", ""]  # fmt: skip
    rec = recognition_by_occlusion([r for r in sc if r["split"] == "validation"] or sc)
    if rec:
        lines += ["### Recognition rate against occlusion (Fig. 6.40 form; validation split)", "",
                  f"Recognised = found with rotation error <= {ROT_OK_DEG:g} deg and translation "
                  f"error <= {TRANS_OK:g} model diagonals.", "",
                  "| occlusion | objects | recognition rate |", "|---|---|---|"]  # fmt: skip
        lines += [f"| {b} | {n} | {v:.3f} |" for b, n, v in rec]
        lines.append("")
    mk = [r for r in rows if r.get("part") == "milk"]
    if mk:
        lines += ["### PCL milk scene (real Kinect scan)", "",
                  "| case | found | h | rotation error (deg) | translation error (diag) | s |",
                  "|---|---|---|---|---|---|"]  # fmt: skip
        for r in mk:
            lines.append(f"| {r['note']} | {fmt_cell(r['found'])} | {fmt_cell(r['h'])} | "
                         f"{fmt_cell(r['rot_err_deg'])} | {fmt_cell(r['trans_err'])} | "
                         f"{fmt_cell(r['seconds'])} |")  # fmt: skip
        lines.append("")
    db = [r for r in rows if r.get("part") == "dbscan"]
    if db:
        lines += ["### Segmentation speed (Table 6.6 form; single thread)", "",
                  "sklearn = scikit-learn's DBSCAN with its k-d tree neighbour search; brute = the "
                  "same with the exhaustive O(n^2) search (the original DBSCAN of Table 6.6). "
                  "ARI: agreement with the adaptive labels.", "",
                  "| scene | points | adaptive DBSCAN (s) | clusters | sklearn (s) | clusters | ARI "
                  "| speed-up | sklearn brute (s) | speed-up |",
                  "|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
        for name in dict.fromkeys(r["scene"] for r in db):
            a = next(r for r in db if r["scene"] == name and r["method"].startswith("adaptive"))
            b = next(r for r in db if r["scene"] == name and r["method"].startswith("sklearn"))
            c = next((r for r in db if r["scene"] == name and r["method"].endswith("brute")), None)
            tail = (f" {c['seconds']:.2f} | x{c['seconds'] / max(a['seconds'], 1e-9):.0f} |"
                    if c else " - | - |")  # fmt: skip
            lines.append(f"| {name} | {a['n_points']} | {a['seconds']:.3f} | {a['n_clusters']} | "
                         f"{b['seconds']:.3f} | {b['n_clusters']} | {a['ari']:.3f} | "
                         f"x{b['seconds'] / max(a['seconds'], 1e-9):.1f} |" + tail)  # fmt: skip
    return "\n".join(lines)


def format_csv(rows: list[dict]) -> str:
    return rows_to_csv(rows, COLUMNS)


def write_tables(rows: list[dict], out) -> tuple[Path, Path]:
    """``<out>.md``, ``<out>.csv`` and (with matplotlib) ``<out>.png`` (recognition vs occlusion)."""
    md, cs = write_section(
        out,
        "Identification in cluttered scans (Section 6.2)",
        "Produced by `spectrageo evaluate identify`.",
        format_markdown(rows),
        format_csv(rows),
    )
    _plot(rows, md.with_suffix(".png"))
    return md, cs


def _plot(rows: list[dict], png: Path) -> Path | None:
    if not have("matplotlib"):
        return None
    plt = pyplot()

    sc = [r for r in rows if r.get("part") == "scene"]
    fig, ax = plt.subplots(figsize=(6, 4))
    for split, mk in (("tuning", "s--"), ("validation", "o-")):
        rec = recognition_by_occlusion([r for r in sc if r["split"] == split])
        if rec:
            x = [float(b.split("-")[0]) + 0.05 for b, _, _ in rec]
            ax.plot(
                x,
                [100 * v for _, _, v in rec],
                mk,
                label=f"{split} (n={sum(n for _, n, _ in rec)})",
            )
    ax.set_xlabel("occlusion")
    ax.set_ylabel("recognition rate (%)")
    ax.set_ylim(0, 105)
    ax.grid(True, alpha=0.3)
    ax.legend()
    ax.set_title("Recognition rate vs occlusion (Fig. 6.40 form)")
    fig.tight_layout()
    return save_png(fig, png)


__all__ = ["COLUMNS", "LIBRARY", "REPORTED_TUNING", "TUNING", "VALIDATION", "evaluate", "format_csv",
           "format_markdown", "load_library", "parse_seeds", "recognition_by_occlusion",
           "write_tables"]  # fmt: skip
