"""Training of the shipped weights (``spectrageo train dae|bm3d-cnn``); needs torch.

Clean meshes (:data:`TRAIN_MESHES`, held out of the denoising protocol's validation split and
benchmark shapes) corrupted by Gaussian noise along the normals at :data:`TRAIN_LEVELS`; one
model for all levels. Everything is seeded.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from .._validation import options_with_legacy
from ..datasets.splits import LEARN_REPORT_MESH
from . import _features as fe
from ._options import (
    TRAIN_LEVELS,
    TRAIN_MESHES,
    BM3DCNNTrainOptions,
    DAETrainOptions,
    check_training_meshes,
)
from ._weights import package_version, save_weights

#: mesh whose noisy versions give the validation theta of the training report (no choice uses it)
REPORT_MESH = LEARN_REPORT_MESH
REPORT_LEVELS = (0.3, 0.5)


def _load(data_dir: Path, rel: str):
    from .. import io

    path = Path(data_dir) / rel
    if not path.is_file():
        raise InvalidInputError(f"training mesh {rel!r} not found under {data_dir}.")
    m = io.read_mesh(path)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def _noisy(V, F, rel: str, level: float, seed: int):
    from ..noise import generate
    from ..noise.generator import case_seed

    return generate(
        V, F, kind="gaussian-normal", level=level, rng=case_seed("train", rel, level, seed=seed)
    ).vertices


def _log(log, msg: str) -> None:
    if log is not None:
        log(msg)


def _theta(X, V0, F) -> float:
    from ..metrics import theta_deg

    return float(theta_deg(X, V0, F))


# --------------------------------------------------------------------------- bm3d-cnn
def _bm3d_stage_data(cases, model, stage, per_case, gen, kernel, channels):
    """Images, eigenvalues and targets of one cascade stage over all training cases."""
    from ..geometry import face_normals

    Xs, Ys = [], []
    for case in cases:
        V0, F, X = case["clean"], case["faces"], case["current"]
        sel = np.arange(F.shape[0])
        if sel.size > per_case:
            sel = np.sort(gen.choice(sel.size, per_case, replace=False))
        img, R = fe.build_images(X, F, rows=kernel, channels=channels, faces=sel)
        Nc = face_normals(V0, F)[sel]
        Xs.append(img)
        Ys.append(np.einsum("mij,mj->mi", R[sel], Nc).astype(np.float32))
    return np.concatenate(Xs), np.concatenate(Ys)


def _advance(cases, model, stage, vertex_iter):
    from ..denoise._normals import fast_update_vertices

    for case in cases:
        N = model.filter_normals(case["current"], case["faces"], stage)
        case["current"] = fast_update_vertices(case["current"], case["faces"], N, vertex_iter)


def _run_meta(meshes, levels, per_case, seed, epochs, dev, train_s) -> dict:
    """Metadata of a training run shared by both models (stored in the weights file)."""
    return {
        "training_meshes": list(meshes),
        "noise": "gaussian-normal",
        "noise_levels": list(levels),
        "samples_per_case": int(per_case),
        "seed": int(seed),
        "epochs": int(epochs),
        "device": str(dev),
        "train_seconds": round(train_s, 1),
        "spectrageo_version": package_version(),
    }


def _finish(out, arrays, meta, loss, data_dir, method, seed, report) -> dict:
    """Save the weights and, with ``report``, the validation theta and the training report."""
    path = save_weights(out, arrays, meta)
    summary = {"weights": str(path), "meta": meta, "loss": loss}
    if report:
        summary["validation"] = _report_theta(data_dir, method, path, seed)
        write_report(path, summary)
    return summary


def train_bm3d_cnn(
    data_dir, out, options: BM3DCNNTrainOptions | None = None, *, log=print, **legacy
) -> dict:
    """Train the bm3d-cnn weights (Section 5.1.4, Algorithm 5) into ``out`` (``.npz``) with a report.

    Stage ``s`` of the cascade is trained on the training cases after stages ``1..s-1``; its class
    centres are the kappa-means (kappa = 3) centres of its images' first-row eigenvalues. ``data_dir``
    is the shared data folder; ``options`` a :class:`BM3DCNNTrainOptions` (old keywords are
    deprecated); ``log`` receives progress lines. Returns the training summary (also
    ``<out>.json``).
    """
    from . import _torch as tt
    from .bm3d_cnn import BM3DCNNModel

    o = options_with_legacy(options, legacy, BM3DCNNTrainOptions, "train_bm3d_cnn")
    epochs, n_stages, seed, meshes, levels = o.epochs, o.n_stages, o.seed, o.meshes, o.levels
    per_case, width, kernel, channels = o.per_case, o.width, o.kernel, o.channels
    vertex_iter, batch_size, lr, start = o.vertex_iter, o.batch_size, o.lr, o.start
    device, threads, report = o.device, o.threads, o.report
    data_dir = Path(data_dir)
    dev = tt.setup(seed, device=device, threads=threads)
    gen = np.random.default_rng(seed)
    t0 = time.perf_counter()
    cases = []
    for rel in meshes:
        V0, F = _load(data_dir, rel)
        for lv in levels:
            cases.append(
                {
                    "mesh": rel,
                    "level": lv,
                    "clean": V0,
                    "faces": F,
                    "current": _noisy(V0, F, rel, lv, seed),
                }
            )
            if start is not None:
                cases[-1]["current"] = np.asarray(start(cases[-1]["current"], F), dtype=np.float64)
    stacks: dict[str, list] = {k: [] for k in ("class_centres", "W1", "b1", "rw", "W2", "b2")}
    history = []
    mu = None
    for s in range(n_stages):
        X, Y = _bm3d_stage_data(cases, None, s, per_case, gen, kernel, channels)
        lam = fe.row_eigenvalues(X[:, :3, 0, :])
        sub = lam if lam.shape[0] <= 50000 else lam[gen.choice(lam.shape[0], 50000, replace=False)]
        centres = fe.kmeans(sub, 3, rng=gen)
        cls = fe.assign_classes(lam, centres)
        nval = max(1, X.shape[0] // 20)
        perm = gen.permutation(X.shape[0])
        va, tr = perm[:nval], perm[nval:]
        _log(
            log,
            f"stage {s + 1}/{n_stages}: {tr.size} training images, classes {np.bincount(cls, minlength=3).tolist()}",
        )
        net = tt.ShrinkageCNN(3, channels, width, kernel)
        hist = tt.fit(
            net,
            X[tr],
            cls[tr],
            Y[tr],
            epochs=epochs,
            device=dev,
            seed=seed + s,
            batch_size=batch_size,
            lr=lr,
            val=(X[va], cls[va], Y[va]),
            log=log,
        )
        history.append(hist)
        w = net.export()
        mu = w.pop("mu")
        for k in ("W1", "b1", "rw", "W2", "b2"):
            stacks[k].append(w[k])
        stacks["class_centres"].append(centres)
        arrays = {k: np.stack(v) for k, v in stacks.items()} | {"mu": mu}
        model = BM3DCNNModel(arrays | {"s": np.asarray(net.s)}, {"image_cols": fe.IMAGE_COLS})
        if s + 1 < n_stages:
            _advance(cases, model, s, vertex_iter)
    train_s = time.perf_counter() - t0
    meta = {
        "model": "bm3d-cnn",
        "architecture": (
            f"per class (3, kappa-means on first-row eigenvalues): conv {channels}->{width} "
            f"{kernel}x{kernel}, RBF shrinkage ({mu.size} Gaussians, Eq. 5.41), conv {width}->3 "
            f"{kernel}x{kernel}, residual on the centre pixel; {n_stages} cascade stage(s); images "
            f"{kernel}x{fe.IMAGE_COLS} of guided pixels + normals"
        ),
        "image_cols": fe.IMAGE_COLS,
        "rbf_sigma": float(net.s),
        "n_iter": int(n_stages),
        "vertex_iter": int(vertex_iter),
        **_run_meta(meshes, levels, per_case, seed, epochs, dev, train_s),
    }
    if start is not None:
        meta["start"] = getattr(start, "__name__", repr(start))
    return _finish(out, arrays, meta, history, data_dir, "bm3d-cnn", seed, report)


# --------------------------------------------------------------------------- dae
def train_dae(
    data_dir, out, options: DAETrainOptions | None = None, *, log=print, **legacy
) -> dict:
    """Train the static content-wise DAE weights (Section 5.1.3, Algorithm 4) into ``out`` with a report.

    As :func:`train_bm3d_cnn`, with a :class:`DAETrainOptions`.
    """
    from ..geometry import face_normals
    from . import _torch as tt
    from .dae import face_rows, feature_mask, fit_groups, rows_of

    o = options_with_legacy(options, legacy, DAETrainOptions, "train_dae")
    epochs, seed, meshes, levels, per_case = o.epochs, o.seed, o.meshes, o.levels, o.per_case
    n_groups, hidden, vertex_iter = o.n_groups, o.hidden, o.vertex_iter
    device, threads, report = o.device, o.threads, o.report
    data_dir = Path(data_dir)
    dev = tt.setup(seed, device=device, threads=threads)
    gen = np.random.default_rng(seed)
    t0 = time.perf_counter()
    Xs, Ys, Fs = [], [], []
    for rel in meshes:
        V0, F = _load(data_dir, rel)
        Nc = face_normals(V0, F)
        for lv in levels:
            rows, R, idx, _ = face_rows(_noisy(V0, F, rel, lv, seed), F)
            feat = feature_mask(rows)  # identified per mesh, as at denoising time
            sel = np.arange(F.shape[0])
            if sel.size > per_case:
                sel = np.sort(gen.choice(sel.size, per_case, replace=False))
            Xs.append(rows[sel])
            Ys.append(rows_of(Nc, idx[sel], R[sel]))
            Fs.append(feat[sel])
    X, Y, feat = np.concatenate(Xs), np.concatenate(Ys), np.concatenate(Fs)
    centres = fit_groups(X, feat, n_groups, rng=gen)
    mid = np.empty(X.shape[0], dtype=np.int64)
    for c in (0, 1):
        sel = np.flatnonzero(feat == c)
        mid[sel] = c * n_groups + fe.assign_classes(X[sel], centres[c])
    nval = max(1, X.shape[0] // 20)
    perm = gen.permutation(X.shape[0])
    va, tr = perm[:nval], perm[nval:]
    _log(
        log,
        f"dae: {tr.size} training rows, rows per model {np.bincount(mid, minlength=2 * n_groups).tolist()}",
    )
    net = tt.ContentDAE(2 * n_groups, X.shape[1], hidden)
    hist = tt.fit(
        net,
        X[tr],
        mid[tr],
        Y[tr],
        epochs=epochs,
        device=dev,
        seed=seed,
        val=(X[va], mid[va], Y[va]),
        log=log,
    )
    arrays = net.export() | {"centres": centres}
    train_s = time.perf_counter() - t0
    meta = {
        "model": "dae",
        "architecture": f"content-wise DAE: 2 classes (RPCA features) x {n_groups} kappa-means groups, {X.shape[1]}-{hidden}-{X.shape[1]} tanh",
        "activation": "tanh",
        "image_cols": fe.IMAGE_COLS,
        "feature_threshold": 0.7,
        "n_iter": 1,
        "vertex_iter": int(vertex_iter),
        **_run_meta(meshes, levels, per_case, seed, epochs, dev, train_s),
    }
    return _finish(out, arrays, meta, [hist], data_dir, "dae", seed, report)


# --------------------------------------------------------------------------- report
def _report_theta(data_dir: Path, model: str, weights: Path, seed: int) -> list[dict]:
    """Theta of the noisy input and of ``model`` on :data:`REPORT_MESH` at :data:`REPORT_LEVELS`."""
    from .bm3d_cnn import bm3d_cnn
    from .dae import dae

    func = bm3d_cnn if model == "bm3d-cnn" else dae
    path = Path(data_dir) / REPORT_MESH
    if not path.is_file():
        return []
    V0, F = _load(data_dir, REPORT_MESH)
    rows = []
    for lv in REPORT_LEVELS:
        Vn = _noisy(V0, F, REPORT_MESH, lv, seed + 1)
        t = time.perf_counter()
        X = func(Vn, F, weights=weights)
        rows.append(
            {
                "mesh": REPORT_MESH,
                "level": lv,
                "input_theta": _theta(Vn, V0, F),
                "theta": _theta(X, V0, F),
                "seconds": time.perf_counter() - t,
            }
        )
    return rows


def write_report(weights: Path, summary: dict) -> list[Path]:
    """``<weights>.json``, ``<weights>.md`` and (with matplotlib) ``<weights>_loss.png``."""
    weights = Path(weights)
    base = weights.with_suffix("")
    paths = []
    js = base.with_suffix(".json")
    js.write_text(json.dumps(summary, indent=1, default=float))
    paths.append(js)
    meta = summary["meta"]
    lines = [f"# Training report: {meta['model']}", "", f"- weights: `{weights.name}`"]
    for k in (
        "architecture",
        "training_meshes",
        "noise",
        "noise_levels",
        "epochs",
        "seed",
        "device",
        "train_seconds",
    ):
        lines.append(f"- {k}: {meta.get(k)}")
    lines += [
        "",
        "## Loss (mean squared error)",
        "",
        "| stage | epoch | train | validation |",
        "|---|---|---|---|",
    ]
    for s, h in enumerate(summary["loss"]):
        for e, tr in enumerate(h["train"]):
            va = h["val"][e] if e < len(h.get("val", [])) else float("nan")
            lines.append(f"| {s + 1} | {e + 1} | {tr:.5f} | {va:.5f} |")
    val = summary.get("validation") or []
    if val:
        lines += [
            "",
            f"## Validation theta (degrees) on {REPORT_MESH} (never trained on)",
            "",
            "| level | noisy | model | seconds |",
            "|---|---|---|---|",
        ]
        for r in val:
            lines.append(
                f"| {r['level']:g} | {r['input_theta']:.2f} | {r['theta']:.2f} | {r['seconds']:.1f} |"
            )
    md = base.with_suffix(".md")
    md.write_text("\n".join(lines) + "\n")
    paths.append(md)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return paths
    fig, ax = plt.subplots(figsize=(6, 4))
    for s, h in enumerate(summary["loss"]):
        ax.plot(range(1, len(h["train"]) + 1), h["train"], label=f"stage {s + 1} train")
        if h.get("val"):
            ax.plot(range(1, len(h["val"]) + 1), h["val"], "--", label=f"stage {s + 1} validation")
    ax.set_xlabel("epoch")
    ax.set_ylabel("MSE")
    ax.set_yscale("log")
    ax.set_title(f"{meta['model']} training loss")
    ax.legend()
    png = Path(str(base) + "_loss.png")
    fig.tight_layout()
    fig.savefig(png, dpi=100)
    plt.close(fig)
    paths.append(png)
    return paths


__all__ = [
    "BM3DCNNTrainOptions",
    "DAETrainOptions",
    "REPORT_MESH",
    "TRAIN_LEVELS",
    "TRAIN_MESHES",
    "check_training_meshes",
    "train_bm3d_cnn",
    "train_dae",
    "write_report",
]
