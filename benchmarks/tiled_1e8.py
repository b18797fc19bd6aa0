"""Issue 21 (a): ``spectrageo outliers --tile`` on a sampled cloud of up to 10^8 points.

1. Generate ``--n`` points (default 10^8) on ``meshes/dragon_vrip.ply.gz``: area-weighted uniform
   samples (as the snippet in ``docs/scaling.md``), moved along their face normal by Gaussian noise
   of standard deviation ``--sigma`` times the expected spacing ``sqrt(area / n)``, plus 1 %
   labelled outliers uniform in the mesh's bounding box enlarged by 5 % of its diagonal (the
   ``"uniform"`` pattern of :func:`spectrageo.noise.corrupt_outliers`, drawn against the mesh box
   so that no kNN pass over the whole cloud is needed). Rows are shuffled within each chunk of
   10^6. Written chunk by chunk as binary little-endian PLY (float32 x, y, z) with the labels
   (True = outlier) in a memory-mapped ``.npy`` beside it; nothing of size n is held in memory.
2. ``spectrageo outliers BIG.ply OUT.ply --tile T --workers 2 --method sor --mask KEEP.npy`` under
   ``/usr/bin/time -f "%e s %M KB"`` (peak RSS of the driver); a background thread samples, every
   second, the summed RSS of the driver and its worker processes (psutil). The command runs
   through :func:`spectrageo.cli.main.main` in a small wrapper that also logs each tile task's
   own duration (``time_s`` of the task result) for the N-machine extrapolation
   (``docs/scaling.md``); the wrapper changes nothing else.
3. On the first ``--n-sub`` rows (default 10^7; a prefix of whole chunks is itself a sample of the
   same distribution) the untiled ``spectrageo outliers`` and the tiled one; F1 of both against
   the labels (target ``|diff| <= 0.005``).
4. ``--scaling``: the subset's tiled run with 1 and 2 workers, and a list-scheduling simulation
   of N workers over the 1-worker task durations (the serial parts measured).

Writes ``benchmarks/_out/tiled_1e8.md`` (and ``.json``). Large files go to ``--dir`` (default
/tmp/t1e8). Usage::

    python benchmarks/tiled_1e8.py --n 10000000 --scaling     # the subset-sized run, minutes
    python benchmarks/tiled_1e8.py                            # 10^8 points
"""

from __future__ import annotations

import argparse
import heapq
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
OUT = HERE / "_out"
CHUNK = 1_000_000


# ----------------------------------------------------------------------------- generation
def _mesh():
    from spectrageo import io

    data = Path(os.environ.get("SPECTRAGEO_DATA", HERE.parent.parent / "shared" / "data"))
    m = io.read(data / "meshes" / "dragon_vrip.ply.gz")
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def generate(path: Path, labels_path: Path, n: int, *, sigma: float, fraction: float, seed: int):
    """Write ``n`` rows to ``path`` (binary PLY float32) and their outlier labels to ``labels_path``."""
    V, F = _mesh()
    e1, e2 = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    cr = np.cross(e1, e2)
    dbl = np.linalg.norm(cr, axis=1)
    ok = dbl > 0
    V0, e1, e2, cr, dbl = V[F[ok, 0]], e1[ok], e2[ok], cr[ok], dbl[ok]
    nrm = cr / dbl[:, None]
    cdf = np.cumsum(dbl)
    cdf /= cdf[-1]
    area = 0.5 * float(dbl.sum())
    noise = sigma * np.sqrt(area / n)
    lo, hi = V.min(axis=0), V.max(axis=0)
    pad = 0.05 * float(np.linalg.norm(hi - lo))
    rng = np.random.default_rng(seed)
    header = (
        f"ply\nformat binary_little_endian 1.0\ncomment tiled_1e8 dragon sample seed {seed}\n"
        f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    ).encode()
    labels = np.lib.format.open_memmap(labels_path, mode="w+", dtype=bool, shape=(n,))
    tmp = path.with_suffix(".part")
    with open(tmp, "wb") as fh:
        fh.write(header)
        for a in range(0, n, CHUNK):
            c = min(CHUNK, n - a)
            m_out = int(round(fraction * c))
            m_in = c - m_out
            f = np.minimum(np.searchsorted(cdf, rng.random(m_in)), len(cdf) - 1)
            u, v = rng.random((2, m_in))
            s = u + v > 1
            u[s], v[s] = 1 - u[s], 1 - v[s]
            P = V0[f] + u[:, None] * e1[f] + v[:, None] * e2[f]
            P += (noise * rng.standard_normal(m_in))[:, None] * nrm[f]
            Q = rng.uniform(lo - pad, hi + pad, (m_out, 3))
            X = np.concatenate([P, Q])
            lab = np.r_[np.zeros(m_in, bool), np.ones(m_out, bool)]
            perm = rng.permutation(c)
            fh.write(np.ascontiguousarray(X[perm], dtype="<f4").tobytes())
            labels[a : a + c] = lab[perm]
    labels.flush()
    del labels
    os.replace(tmp, path)
    return {"area": area, "noise_sigma": noise, "bbox_pad": pad}


def write_prefix(src: Path, labels_src: Path, dst: Path, labels_dst: Path, n_sub: int) -> None:
    """The first ``n_sub`` rows of a float32 PLY written by :func:`generate` (and their labels)."""
    with open(src, "rb") as fh:
        head = fh.read(4096)
    end = head.index(b"end_header\n") + len(b"end_header\n")
    n = int(head.split(b"element vertex ")[1].split(b"\n")[0])
    rec = np.memmap(src, dtype="<f4", mode="r", offset=end, shape=(n, 3))
    header = head[:end].replace(
        f"element vertex {n}\n".encode(), f"element vertex {n_sub}\n".encode()
    )
    with open(dst, "wb") as fh:
        fh.write(header)
        for a in range(0, n_sub, CHUNK):
            fh.write(np.ascontiguousarray(rec[a : min(n_sub, a + CHUNK)]).tobytes())
    np.save(labels_dst, np.load(labels_src, mmap_mode="r")[:n_sub])


# ----------------------------------------------------------------------------- runs
class RssSampler(threading.Thread):
    """Every second: summed RSS of a process and its descendants; keeps the peaks."""

    def __init__(self, pid: int):
        super().__init__(daemon=True)
        self.pid, self.stop, self.peak_total, self.peak_single = pid, threading.Event(), 0, 0

    def run(self):
        import psutil

        try:
            root = psutil.Process(self.pid)
        except psutil.Error:
            return
        while not self.stop.is_set():
            try:
                procs = [root, *root.children(recursive=True)]
            except psutil.Error:
                break
            rss = []
            for p in procs:
                try:
                    rss.append(p.memory_info().rss)
                except psutil.Error:
                    pass
            if rss:
                self.peak_total = max(self.peak_total, sum(rss))
                self.peak_single = max(self.peak_single, max(rss))
            self.stop.wait(1.0)


def run_cli(args: list[str], *, task_log: Path | None = None) -> dict:
    """``spectrageo ARGS`` under ``/usr/bin/time``; wall time, driver peak, sampled totals."""
    if task_log is not None:
        cmd = [sys.executable, str(Path(__file__).resolve()), "_timed", str(task_log), *args]
    else:
        cmd = [sys.executable, "-m", "spectrageo.cli.main", *args]
    fd, name = tempfile.mkstemp(suffix=".time.txt")  # /usr/bin/time's report (any --dir)
    os.close(fd)
    timef = Path(name)
    full = ["/usr/bin/time", "-o", str(timef), "-f", "%e s %M KB", *cmd]
    t0 = time.perf_counter()
    p = subprocess.Popen(full, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sampler = RssSampler(p.pid)
    sampler.start()
    out, err = p.communicate()
    wall = time.perf_counter() - t0
    sampler.stop.set()
    sampler.join()
    report = timef.read_text()
    timef.unlink()
    if p.returncode != 0:
        raise SystemExit(f"failed: {' '.join(args)}\n{out}\n{err}")
    e, _, m, _ = report.split()[-4:]
    return {
        "cmd": "spectrageo " + " ".join(args),
        "time_s": float(e),
        "wall_s": round(wall, 2),
        "driver_peak_mb": int(m) / 1024.0,
        "sampled_total_peak_mb": sampler.peak_total / 2**20,
        "sampled_single_peak_mb": sampler.peak_single / 2**20,
        "status": err.strip().splitlines()[-1] if err.strip() else "",
    }


def _timed(log: str, argv: list[str]) -> int:
    """The CLI, logging every tile task's duration (and its arrival time) to ``log``."""
    from spectrageo.cli.main import main
    from spectrageo.distributed import _tiled

    rec: dict = {"tasks": [], "t0": time.perf_counter()}
    orig_map, orig_timing = _tiled._map_tiles, _tiled._timing

    def map_tiles(*a, **k):
        rec["t_submit"] = time.perf_counter() - rec["t0"]
        for t, r in orig_map(*a, **k):
            rec["tasks"].append(
                {"t": t, "time_s": r["time_s"], "n_own": int(r["idx"].size),
                 "n_region": r["n_region"], "arrived_s": time.perf_counter() - rec["t0"]}
            )  # fmt: skip
            Path(log).write_text(json.dumps(rec))  # progress survives a stopped run
            yield t, r

    def timing(info, *a, **k):
        out = orig_timing(info, *a, **k)
        rec["info"] = {k2: v for k2, v in out.items() if isinstance(v, (int, float, bool, str))}
        rec["info"]["n_tiles"] = int(a[0].n_tiles)
        return out

    _tiled._map_tiles, _tiled._timing = map_tiles, timing
    try:
        return main(argv)
    finally:
        rec["t_end"] = time.perf_counter() - rec["t0"]
        Path(log).write_text(json.dumps(rec, indent=1))


def f1(keep: np.ndarray, labels: np.ndarray) -> dict:
    """Outliers are the positive class: predicted = ~keep."""
    tp = fp = fn = 0
    for a in range(0, len(keep), 10 * CHUNK):
        pr, lb = ~np.asarray(keep[a : a + 10 * CHUNK]), np.asarray(labels[a : a + 10 * CHUNK])
        tp += int(np.count_nonzero(pr & lb))
        fp += int(np.count_nonzero(pr & ~lb))
        fn += int(np.count_nonzero(~pr & lb))
    p = tp / max(tp + fp, 1)
    r = tp / max(tp + fn, 1)
    return {"f1": 2 * p * r / max(p + r, 1e-300), "precision": p, "recall": r, "removed": tp + fp}


# ----------------------------------------------------------------------------- simulation
def list_schedule(durations, n_workers: int) -> float:
    """Makespan of greedy list scheduling in submission order (what Dask does with equal tasks)."""
    free = [0.0] * n_workers
    for d in durations:
        t = heapq.heappop(free)
        heapq.heappush(free, t + d)
    return max(free)


def simulate(log: dict, ns=(1, 2, 4, 8, 16, 64)) -> dict:
    """Extrapolate a run's wall time to N workers from its task durations and serial parts."""
    info = log["info"]
    tasks = sorted(log["tasks"], key=lambda r: r["t"])
    dur = [r["time_s"] for r in tasks]
    tile_phase = info["time_tiles_s"]  # cluster start + tasks + gathering
    first = log["t_submit"]
    makespan_meas = max(r["arrived_s"] for r in tasks) - first
    overhead = tile_phase - makespan_meas  # cluster start/stop, scatter
    serial = info["time_total_s"] - tile_phase  # 2 streamed passes + threshold + writing pass
    return {
        "n_tasks": len(dur),
        "task_sum_s": sum(dur),
        "task_max_s": max(dur),
        "serial_s": serial,
        "cluster_overhead_s": overhead,
        "measured_total_s": info["time_total_s"],
        "sim": {n: serial + overhead + list_schedule(dur, n) for n in ns},
        "sim_makespan": {n: list_schedule(dur, n) for n in ns},
    }


def extrapolate(log: dict, n_points: int, n_target: int, *, ns=(1, 2, 4, 8, 16, 64)) -> dict:
    """N machines on ``n_target`` points from one measured run of ``n_points`` (its task log).

    Model: the same tile size, so ``T = n_tasks * n_target / n_points`` tasks whose durations are
    the measured ones repeated in order; the driver's streamed passes (read, spill, threshold,
    writing) scale linearly with the points and stay serial; the tile phase is greedy list
    scheduling on N single-task workers (:func:`list_schedule`) plus the measured cluster overhead
    (a cluster that is already running pays only the scatter of the boxes and the gathering).
    """
    sim = simulate(log, ns)
    dur = [r["time_s"] for r in sorted(log["tasks"], key=lambda r: r["t"])]
    scale = n_target / n_points
    T = max(1, round(len(dur) * scale))
    durs = [dur[i % len(dur)] for i in range(T)]
    serial = sim["serial_s"] * scale
    return {
        "n_tasks": T,
        "serial_s": serial,
        "overhead_s": sim["cluster_overhead_s"],
        "total": {n: serial + sim["cluster_overhead_s"] + list_schedule(durs, n) for n in ns},
        "tiles": {n: list_schedule(durs, n) for n in ns},
    }


# ----------------------------------------------------------------------------- main
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=lambda s: int(float(s)), default=100_000_000)
    ap.add_argument("--n-sub", type=lambda s: int(float(s)), default=10_000_000)
    ap.add_argument("--tile", type=int, default=3_000_000)
    ap.add_argument("--sub-tile", type=int, default=None, help="tile of the subset runs (--tile)")
    ap.add_argument("--method", default="sor", choices=["sor", "radius", "rpca"])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--sigma", type=float, default=0.25, help="normal noise, x expected spacing")
    ap.add_argument("--fraction", type=float, default=0.01)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--dir", default="/tmp/t1e8")
    ap.add_argument("--scaling", action="store_true", help="subset: 1- and 2-worker runs")
    ap.add_argument("--skip-big", action="store_true", help="subset runs only")
    ap.add_argument("--keep-files", action="store_true")
    ap.add_argument("--report", default="tiled_1e8", help="name of the _out/NAME.md/.json")
    ap.add_argument(
        "--extrapolate", nargs=2, default=None, metavar=("TASKS_JSON", "N_POINTS"),
        help="only print the N-machine extrapolation to --n points from a run's task log",
    )  # fmt: skip
    ap.add_argument(
        "--combine", nargs="+", default=None, metavar="JSON",
        help="only render earlier runs' JSON files into one report",
    )  # fmt: skip
    a = ap.parse_args(argv)
    if a.combine:
        text = "\n".join(report(json.loads(Path(j).read_text())) for j in a.combine)
        (OUT / f"{a.report}.md").write_text(text)
        print(text)
        return 0
    if a.extrapolate:
        lg = json.loads(Path(a.extrapolate[0]).read_text())
        e = extrapolate(lg, int(float(a.extrapolate[1])), a.n)
        print(
            f"{e['n_tasks']} tasks, serial {e['serial_s']:.1f} s, overhead {e['overhead_s']:.1f} s"
        )
        print("| workers | tile phase | total |\n|---:|---:|---:|")
        for n, v in e["total"].items():
            print(f"| {n} | {e['tiles'][n]:.0f} s | {v:.0f} s |")
        return 0
    d = Path(a.dir)
    d.mkdir(parents=True, exist_ok=True)
    OUT.mkdir(exist_ok=True)
    tag = f"{a.n:.0e}".replace("+0", "").replace("+", "")
    big, big_lab = d / f"dragon_{tag}.ply", d / f"dragon_{tag}_labels.npy"
    res: dict = {"n": a.n, "n_sub": a.n_sub, "tile": a.tile, "method": a.method,
                 "workers": a.workers, "cpus": os.cpu_count(), "runs": {}}  # fmt: skip
    res["load_before"] = os.getloadavg()
    res["code"] = _commit()
    t = time.perf_counter()
    if not big.exists() or not big_lab.exists():
        res["gen"] = generate(big, big_lab, a.n, sigma=a.sigma, fraction=a.fraction, seed=a.seed)
    res["gen_time_s"] = round(time.perf_counter() - t, 1)
    res["input_bytes"] = big.stat().st_size
    print(f"generated {a.n} points in {res['gen_time_s']} s", file=sys.stderr, flush=True)
    labels = np.load(big_lab, mmap_mode="r")
    common = ["--method", a.method]
    sub_tile = a.sub_tile or a.tile

    if not a.skip_big:
        keep = d / "keep_big.npy"
        r = run_cli(["outliers", str(big), str(d / "out_big.ply"), *common, "--tile", str(a.tile),
                     "--workers", str(a.workers), "--mask", str(keep)],
                    task_log=d / "tasks_big.json")  # fmt: skip
        r.update(f1(np.load(keep, mmap_mode="r"), labels))
        r["log"] = json.loads((d / "tasks_big.json").read_text())["info"]
        res["runs"]["big_tiled"] = r
        print(json.dumps(r), file=sys.stderr, flush=True)
        if not a.keep_files:
            (d / "out_big.ply").unlink(missing_ok=True)

    if a.n_sub:
        if a.n_sub < a.n:
            sub, sub_lab = d / f"sub_{a.n_sub}.ply", d / f"sub_{a.n_sub}_labels.npy"
            write_prefix(big, big_lab, sub, sub_lab, a.n_sub)
        else:
            sub, sub_lab = big, big_lab
        lab_sub = np.load(sub_lab)
        runs = [("sub_untiled", ["outliers", str(sub), str(d / "o_u.ply"), *common, "--mask",
                                 str(d / "k_u.npy")], None)]  # fmt: skip
        wl = (1, a.workers) if a.scaling else (a.workers,)
        for w in wl:
            runs.append((f"sub_tiled_w{w}", ["outliers", str(sub), str(d / f"o_t{w}.ply"), *common, "--tile",
                         str(sub_tile), "--workers", str(w), "--mask", str(d / f"k_t{w}.npy")],
                         d / f"tasks_sub_w{w}.json"))  # fmt: skip
        for name, args, log in runs:
            r = run_cli(args, task_log=log)
            r.update(f1(np.load(args[args.index("--mask") + 1]), lab_sub))
            if log is not None:
                lg = json.loads(log.read_text())
                r["log"] = lg["info"]
                r["sim"] = simulate(lg)
            res["runs"][name] = r
            print(name, json.dumps(r), file=sys.stderr, flush=True)
            Path(args[2]).unlink(missing_ok=True)
        ku = np.load(d / "k_u.npy")
        for w in wl:
            kt = np.load(d / f"k_t{w}.npy")
            res["runs"][f"sub_tiled_w{w}"]["mask_equal_untiled"] = float(np.mean(kt == ku))
    res["load_after"] = os.getloadavg()
    (OUT / f"{a.report}.json").write_text(json.dumps(res, indent=1, default=str))
    (OUT / f"{a.report}.md").write_text(report(res))
    print(report(res))
    return 0


def _commit() -> str:
    """The checkout's commit (the code the runs used, uncommitted edits aside)."""
    try:
        out = subprocess.run(
            ["git", "-C", str(HERE.parent), "rev-parse", "--short", "HEAD"],
            capture_output=True, text=True, timeout=10,
        )  # fmt: skip
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def report(res: dict) -> str:
    gen = f"generated in {res['gen_time_s']} s" if "gen" in res else "file of an earlier run"
    L = [
        "# Tiled outliers on a sampled dragon (issue 21)",
        "",
        f"`python benchmarks/tiled_1e8.py --n {res['n']}` -- {res['n']:,} points "
        f"({res['input_bytes'] / 1e9:.2f} GB binary PLY float32, {gen}), "
        f"1 % uniform outliers; method `{res['method']}`, tile {res['tile']:,}; "
        f"{res['cpus']} cores (shared), load average before {res['load_before'][0]:.1f}, "
        f"after {res['load_after'][0]:.1f}; code at commit {res.get('code', 'unknown')}.",
        "",
        "| run | N | time | driver peak RSS | sampled peak, all processes | tiles | halo | F1 | "
        "precision | recall |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, r in res["runs"].items():
        n = res["n"] if name.startswith("big") else res["n_sub"]
        lg = r.get("log", {})
        L.append(
            f"| {name} | {n:,} | {r['time_s']:.1f} s | {r['driver_peak_mb']:,.0f} MB | "
            f"{r['sampled_total_peak_mb']:,.0f} MB | {lg.get('n_tiles', '-')} | "
            f"{'+%.0f %%' % (100 * lg['halo_fraction_mean']) if lg else '-'} | {r['f1']:.4f} | "
            f"{r['precision']:.4f} | {r['recall']:.4f} |"
        )
    L.append("")
    if "sub_untiled" in res["runs"]:
        fu = res["runs"]["sub_untiled"]["f1"]
        for name, r in res["runs"].items():
            if name.startswith("sub_tiled"):
                L.append(
                    f"- {name}: F1 {r['f1']:.5f} vs untiled {fu:.5f} (diff "
                    f"{r['f1'] - fu:+.5f}); keep masks equal on {100 * r['mask_equal_untiled']:.4f} %"
                )
    for name, r in res["runs"].items():
        if "log" in r:
            lg = r["log"]
            L.append(
                f"- {name} phases: read {lg.get('time_read_s')} s, spill {lg.get('time_spill_s')} s, "
                f"tiles {lg.get('time_tiles_s')} s, total {lg.get('time_total_s')} s"
            )
        if "sim" in r:
            s = r["sim"]
            L.append(
                f"  - {s['n_tasks']} tasks, sum {s['task_sum_s']:.1f} s, max {s['task_max_s']:.1f} s; "
                f"serial {s['serial_s']:.1f} s, cluster overhead {s['cluster_overhead_s']:.1f} s; "
                "simulated total for N workers: "
                + ", ".join(f"{k}: {v:.1f} s" for k, v in s["sim"].items())
            )
    L.append("")
    L.append("Commands: " + "; ".join(f"`{r['cmd']}`" for r in res["runs"].values()))
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "_timed":
        sys.exit(_timed(sys.argv[2], sys.argv[3:]))
    sys.exit(main())
