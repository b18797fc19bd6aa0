"""Protocol of the denoising evaluation: the pair run and the generality protocol."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from .._progress import progress
from ..datasets.splits import split_of
from ._denoise_cases import (
    COLUMNS,
    PEER_FIXED,
    PEER_GRIDS,
    PEERS,
    PROTOCOL_METHODS,
    GeneralityResult,
    _load_clean,
    protocol_cases,
    setting_label,
)
from ._denoise_report import write_generality, write_tables


def _peer_available(name: str) -> bool:
    mod = name.split("-")[0]
    try:
        __import__(mod)
    except Exception:  # noqa: BLE001 - any import failure means "not available"
        return False
    return True


def _run_peer(name: str, V: np.ndarray, F: np.ndarray, params: dict | None = None) -> np.ndarray:
    """Peer implementations (vertex order is kept by both), with their default parameters or the
    keyword arguments ``params`` of the underlying filter (see :data:`PEER_GRIDS`)."""
    params = dict(params or {})
    if name.startswith("pymeshlab"):
        import pymeshlab

        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F.astype(np.int32)))
        if name == "pymeshlab-twostep":
            ms.apply_coord_two_steps_smoothing(**params)
        else:
            ms.apply_coord_taubin_smoothing(**params)
        out = ms.current_mesh().vertex_matrix()
    else:
        import open3d as o3d

        m = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32))
        )
        out = np.asarray(m.filter_smooth_taubin(**{"number_of_iterations": 10, **params}).vertices)
    out = np.asarray(out, dtype=np.float64)
    if out.shape != V.shape:
        raise RuntimeError(f"{name} changed the vertex count ({V.shape[0]} -> {out.shape[0]}).")
    return out


def _row(pair: str, method: str, X, V0, F, dt: float, hd: bool) -> dict:
    from .. import metrics

    met = metrics.compare(X, V0, F, hausdorff_distance=hd)
    r = {"pair": pair, "method": method, "n_vertices": int(X.shape[0])}
    r.update({k: met.get(k, float("nan")) for k in COLUMNS[3:-2]})
    r["time_s"] = dt
    r["split"] = split_of("denoise", pair) or "-"
    return r


def evaluate_denoise(
    data_dir,
    methods: list[str] | None = None,
    out=None,
    *,
    pairs: list[str] | None = None,
    peers: bool = True,
    hausdorff_distance: bool = True,
) -> list[dict]:
    """Run denoisers on every noisy / original pair and collect the metrics.

    Parameters
    ----------
    data_dir : path
        The shared data folder (holding ``denoise/``) or the ``denoise`` folder itself.
    methods : list of str, optional
        Registered denoisers and/or peers (:data:`PEERS`); default every registered denoiser plus
        the importable peers. ``"<method>+coarse"`` runs the method after the TSGSP coarse step.
    out : path, optional
        Writes ``<out>.md`` and ``<out>.csv`` atomically (a ``.md``/``.csv`` suffix is dropped).
    pairs : list of str, optional
        Subset of pair names (e.g. ``["Fandisk0.7"]``).
    peers : bool
        Include the importable peers when ``methods`` is None.
    hausdorff_distance : bool
        Compute the (costliest) Hausdorff column.

    Returns
    -------
    list of dict, one row per (pair, method) with the keys of :data:`COLUMNS`; the noisy input is
    reported as method ``"noisy"``; ``split`` is the pair's split in the registry (``"-"`` for a
    pair it does not list).
    """
    from .. import denoise, io
    from ..datasets import denoise_pairs
    from ..denoise._registry import warm_up

    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise InvalidInputError(f"`data_dir` must be a folder; got {data_dir}.")
    found = denoise_pairs(data_dir)
    if not found:
        raise InvalidInputError(f"no noisy/original pairs found under {data_dir}.")
    if pairs is not None:
        unknown = sorted(set(pairs) - {p[0] for p in found})
        if unknown:
            raise InvalidInputError(f"unknown pairs {unknown}; available: {[p[0] for p in found]}.")
        found = [p for p in found if p[0] in pairs]
    if methods is None:
        methods = denoise.available() + ([p for p in PEERS if _peer_available(p)] if peers else [])
    methods = list(methods)
    own = []  # registered denoisers among the methods (warmed up before timing)
    for m in methods:
        base = m[: -len("+coarse")] if m.endswith("+coarse") else m
        if base in PEERS:
            if not _peer_available(base):
                raise InvalidInputError(
                    f"peer {base!r} is not installed (pip install 'spectrageo[bench]')."
                )
        else:
            denoise.get(base)
            own.append(base)
    rows: list[dict] = []
    for name, noisy_path, orig_path in progress(found, desc="denoise pairs", total=len(found)):
        noisy = io.read_mesh(noisy_path)
        orig = io.read_mesh(orig_path)
        V, F, V0 = noisy.vertices, noisy.faces, orig.vertices
        if V.shape != V0.shape:
            raise InvalidInputError(f"pair {name}: noisy and original vertex counts differ.")
        rows.append(_row(name, "noisy", V, V0, F, 0.0, hausdorff_distance))
        if own:  # one-time compilation (numba caches) kept out of the first pair's timings
            warm_up(own, V, F)
            own = []
        for m in methods:
            pre = m.endswith("+coarse")
            base = m[: -len("+coarse")] if pre else m
            t0 = time.perf_counter()
            if base in PEERS:
                if pre:
                    from ..denoise.tsgsp import coarse

                    X = _run_peer(base, coarse(V, F).vertices, F)
                else:
                    X = _run_peer(base, V, F)
            else:
                X = denoise.denoise(V, F, method=base, pre="coarse" if pre else None)
            dt = time.perf_counter() - t0
            rows.append(_row(name, m, X, V0, F, dt, hausdorff_distance))
            if m == "tsgsp":
                rows[-1].update(learned_sizes(V, F))
    if out is not None:
        write_tables(rows, out)
    return rows


def learned_sizes(V, F) -> dict:
    """Distribution of the subspace sizes learned by Algorithm 1 in TSGSP's coarse step (issue
    14): median ``n_l / n_max``, percentage of signals at the ``max_keep`` bound, number of
    submesh x coordinate signals. Extra keys of the ``tsgsp`` rows (not CSV columns)."""
    from ..denoise.tsgsp import coarse

    r = coarse(V, F)
    if r.subspace_sizes.size == 0 or not r.max_sizes.any():
        return {"mbl_median_frac": float("nan"), "mbl_at_bound_pct": float("nan"), "mbl_n": 0}
    frac = r.subspace_sizes / np.maximum(r.max_sizes[:, None], 1)
    return {
        "mbl_median_frac": float(np.median(frac)),
        "mbl_at_bound_pct": 100.0 * float(np.mean(r.subspace_sizes == r.max_sizes[:, None])),
        "mbl_n": int(frac.size),
    }


def _theta(X, V0, F) -> float:
    from .. import metrics

    return float(metrics.theta_deg(X, V0, F))


def _cli_seconds(method: str, in_path: Path, out_path: Path) -> float:
    """Wall time of ``spectrageo denoise IN OUT --method METHOD`` in a fresh process."""
    import os
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "spectrageo.cli.main", "denoise", str(in_path), str(out_path)]
    cmd += ["--method", method]
    env = {**os.environ, "SPECTRAGEO_PROGRESS": "0"}
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr.strip().splitlines()[-1] if proc.stderr else "failed")
    return dt


def choose_fixed(grid: list[dict], cases: list[str] | None = None) -> tuple[dict, dict]:
    """The peers' fixed settings: per peer the grid point with the lowest mean theta over the
    ``cases`` (default every case in ``grid``). A failed run counts as the case's input theta
    (no improvement). Returns ``(fixed params per peer, {peer: {label: mean}})``."""
    keep = None if cases is None else set(cases)
    fixed, means = {}, {}
    for peer, settings in PEER_GRIDS.items():
        by = {setting_label(p): [] for p in settings}
        for g in grid:
            if g["method"] == peer and (keep is None or g["case"] in keep):
                by.setdefault(g["setting"], []).append(g["theta_deg"])
        if not any(by.values()):
            continue
        means[peer] = {k: float(np.mean(v)) for k, v in by.items() if v}
        best = min(means[peer], key=means[peer].get)
        fixed[peer] = next(p for p in settings if setting_label(p) == best)
    return fixed, means


def _peer_grid(case_name: str, split: str, peer: str, Vn, V0, F, input_theta: float) -> list[dict]:
    out = []
    for params in PEER_GRIDS[peer]:
        g = {"split": split, "case": case_name, "method": peer, "setting": setting_label(params)}
        t0 = time.perf_counter()
        try:
            X = _run_peer(peer, Vn, F, params)
            g.update(theta_deg=_theta(X, V0, F), error="")
        except Exception as exc:  # noqa: BLE001 - recorded in the table, the run goes on
            g.update(theta_deg=input_theta, error=f"{type(exc).__name__}: {exc}")
        g["time_s"] = time.perf_counter() - t0
        out.append(g)
    return out


def peer_rows(base: dict, grid: list[dict], fixed: dict) -> list[dict]:
    """``<peer>:fixed`` and ``<peer>:oracle`` rows of one case from its grid results; the oracle is
    the grid point with the lowest theta, so it is never worse than the fixed setting. A grid point
    whose run failed carries the input's theta (as if it returned the input) and its error."""
    rows = []
    for peer in PEER_GRIDS:
        gs = [g for g in grid if g["method"] == peer]
        if not gs:
            continue
        chosen = {
            "fixed": next((g for g in gs if g["setting"] == setting_label(fixed[peer])), None),
            "oracle": min(gs, key=lambda g: g["theta_deg"]),
        }
        for kind, g in chosen.items():
            if g is None:
                continue
            r = dict(base)
            r.update(
                method=f"{peer}:{kind}",
                setting=g["setting"],
                theta_deg=g["theta_deg"],
                above_input=bool(g["theta_deg"] > base["input_theta"]),
                time_s=g["time_s"],
                cli_time_s=float("nan"),
                error=g["error"],
            )
            rows.append(r)
    return rows


def evaluate_generality(
    data_dir,
    *,
    split: str = "both",
    levels=None,
    kinds=None,
    max_vertices: int | None = None,
    models: list[str] | None = None,
    methods=PROTOCOL_METHODS,
    peers: bool = True,
    cli_timing: bool = False,
    repeat: int = 1,
    seed: int = 0,
    out=None,
) -> GeneralityResult:
    """The generality protocol of issue 14: the package's denoisers and the peers on the tuning
    and/or validation split (:data:`TUNING_PAIRS`, :data:`TUNING_MESHES`,
    :data:`VALIDATION_MESHES`), with the peers at their fixed setting and per-case oracle.

    Parameters
    ----------
    data_dir : path
        The shared data folder.
    split : {"tuning", "validation", "both"}
    levels : sequence of float, optional
        Relative noise levels of the generated cases (default
        :data:`spectrageo.noise.GENERATOR_LEVELS`); the pairs keep their own noise.
    kinds : sequence of str, optional
        Corruption kinds (default :data:`spectrageo.noise.GENERATOR_KINDS`).
    max_vertices : int, optional
        Skip models with more vertices (to fit a small machine); the report lists what was run.
    models : list of str, optional
        Keep only these models (pair name, path relative to the data folder, label such as
        ``cad/joint`` or file stem such as ``partLp``).
    methods : sequence of str
        Registered denoisers run with default settings (warmed up once before timing, so numba
        compilation is not timed), default :data:`PROTOCOL_METHODS`.
    peers : bool
        Run the peers (:data:`PEER_GRIDS`) that are importable.
    cli_timing : bool
        Also time ``spectrageo denoise`` in a fresh process per case and method (after one untimed
        run that fills the numba cache); reported as ``cli_time_s``.
    repeat : int
        In-process times of the package's methods are the best of ``repeat`` runs (the outputs
        are deterministic, so theta is that of the first run): a per-case time ratio is
        otherwise as noisy as the machine's scheduling. CLI times are one fresh process each.
    seed : int
        Added to every generated case's seed.
    out : path, optional
        Writes ``<out>.md``, ``<out>.csv``, ``<out>_grid.csv`` and ``<out>.png`` (matplotlib).

    Returns
    -------
    GeneralityResult
    """
    import tempfile

    from .. import denoise, io
    from ..denoise._registry import warm_up
    from ..geometry import Mesh
    from ..noise.generator import generate

    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise InvalidInputError(f"`data_dir` must be a folder; got {data_dir}.")
    if max_vertices is not None and (isinstance(max_vertices, bool) or int(max_vertices) < 1):
        raise InvalidInputError(f"`max_vertices` must be a positive integer; got {max_vertices!r}.")
    methods = list(methods)
    for m in methods:
        denoise.get(m)
    if isinstance(repeat, bool) or not isinstance(repeat, int | np.integer) or repeat < 1:
        raise InvalidInputError(f"`repeat` must be a positive integer; got {repeat!r}.")
    peer_names = [p for p in PEER_GRIDS if _peer_available(p)] if peers else []
    cases = protocol_cases(split, levels=levels, kinds=kinds, seed=seed)
    if models is not None:
        want = set(models)
        cases = [
            c for c in cases if want & {c.model, c.label, Path(c.label).name, Path(c.model).name}
        ]
        if not cases:
            raise InvalidInputError(f"no protocol case matches `models`={sorted(want)}.")
    rows: list[dict] = []
    grid: list[dict] = []
    warmed = False
    loaded: tuple = (None, None)
    with tempfile.TemporaryDirectory(prefix="spectrageo-gen-") as tmp:
        tmpdir = Path(tmp)
        for case in progress(cases, desc="generality cases", total=len(cases)):
            if loaded[0] != case.model:
                loaded = (case.model, _load_clean(data_dir, case))
            V_given, V0, F = loaded[1]
            if max_vertices is not None and V0.shape[0] > int(max_vertices):
                continue
            if case.corruption == "pair":
                Vn = V_given
            else:
                Vn = generate(V0, F, kind=case.corruption, level=case.level, rng=case.seed).vertices
            input_theta = _theta(Vn, V0, F)
            base = {
                "split": case.split,
                "case": case.name,
                "model": case.label,
                "corruption": case.corruption,
                "level": case.level,
                "n_vertices": int(V0.shape[0]),
                "input_theta": input_theta,
            }
            if not warmed and methods:  # numba compilation kept out of every timing
                warm_up(methods, Vn, F)
            in_path = tmpdir / "input.ply"
            if cli_timing and methods:
                io.write(in_path, Mesh(Vn, F))
                if not warmed:
                    for m in methods:  # fills the on-disk numba cache of a fresh process
                        try:
                            _cli_seconds(m, in_path, tmpdir / "out.ply")
                        except RuntimeError:
                            pass
            warmed = True
            for m in methods:
                r = dict(base, method=m, setting="default", cli_time_s=float("nan"), error="")
                t0 = time.perf_counter()
                try:
                    X = denoise.denoise(Vn, F, method=m)
                    r["time_s"] = time.perf_counter() - t0
                    r["theta_deg"] = _theta(X, V0, F)
                    for _ in range(repeat - 1):
                        t0 = time.perf_counter()
                        denoise.denoise(Vn, F, method=m)
                        r["time_s"] = min(r["time_s"], time.perf_counter() - t0)
                except Exception as exc:  # noqa: BLE001 - recorded in the table
                    r.update(time_s=time.perf_counter() - t0, theta_deg=float("nan"))
                    r["error"] = f"{type(exc).__name__}: {exc}"
                r["above_input"] = bool(r["theta_deg"] > input_theta)
                if cli_timing:
                    try:
                        r["cli_time_s"] = _cli_seconds(m, in_path, tmpdir / "out.ply")
                    except RuntimeError as exc:
                        r["error"] = (r["error"] + "; " if r["error"] else "") + f"cli: {exc}"
                rows.append(r)
            for peer in peer_names:
                grid += _peer_grid(case.name, case.split, peer, Vn, V0, F, input_theta)
            rows.append(base)  # placeholder: the peers' rows are added once `fixed` is known
    tuning_cases = [r["case"] for r in rows if r.get("method") is None and r["split"] == "tuning"]
    means: dict = {}
    if tuning_cases and peer_names:
        fixed, means = choose_fixed(grid, tuning_cases)
        source = "tuning run"
    else:
        fixed, source = {p: PEER_FIXED[p] for p in peer_names}, "frozen"
    final: list[dict] = []
    for r in rows:
        if r.get("method") is None:
            final += peer_rows(r, [g for g in grid if g["case"] == r["case"]], fixed)
        else:
            final.append(r)
    result = GeneralityResult(final, grid, fixed, source, means, repeat=int(repeat))
    if out is not None:
        write_generality(result, out)
    return result
