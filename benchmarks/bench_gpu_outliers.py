"""The GPU path of the patch RPCA (``rpca_scores(device=...)``, issue 21) against the numba path.

Same clouds as ``bench_outliers_speed.py`` (points sampled on the Stanford dragon of the shared
data, Gaussian noise of 0.2 spacings along the normal, 10 % ``mixed`` outliers). Per size,
:func:`spectrageo.outliers.rpca_scores` at its defaults runs on

* ``cpu``: the fused numba kernels (the default path);
* ``torch-cpu``: the PyTorch path on ``torch.device("cpu")`` (the GPU code run on the CPU);
* ``cuda``: the PyTorch path on the GPU, when ``torch.cuda.is_available()``;

alternately in one process, best of ``--repeat`` after one warm-up call of each (numba
compilation, CUDA context). Reported: seconds per call, points per second, the ratio to ``cpu``,
ALM iterations and the largest score difference to ``cpu`` (spacings).

    python benchmarks/bench_gpu_outliers.py                   # 100k and 1M points
    python benchmarks/bench_gpu_outliers.py --sizes 100000 --repeat 3
    python benchmarks/bench_gpu_outliers.py --no-torch-cpu    # on a GPU machine: cpu vs cuda

Writes ``benchmarks/_out/bench_gpu_outliers.md``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, write_section  # noqa: E402
from bench_outliers_speed import make_cloud  # noqa: E402

SIZES = (100_000, 1_000_000)


def _paths(torch_cpu: bool) -> list[tuple[str, object]]:
    paths: list[tuple[str, object]] = [("cpu", "cpu")]
    try:
        import torch
    except ImportError:
        return paths
    if torch_cpu:
        paths.append(("torch-cpu", torch.device("cpu")))
    if torch.cuda.is_available():
        paths.append(("cuda", "cuda"))
    return paths


def run(sizes, repeat: int, torch_cpu: bool) -> list[dict]:
    from spectrageo.outliers import rpca_scores

    rows = []
    paths = _paths(torch_cpu)
    for n in sizes:
        P, _ = make_cloud(int(n))
        ref = None
        best = {name: np.inf for name, _ in paths}
        res = {}
        for name, dev in paths:  # warm-up
            res[name] = rpca_scores(P, device=dev)
        for _ in range(repeat):
            for name, dev in paths:
                t0 = time.perf_counter()
                res[name] = rpca_scores(P, device=dev)
                best[name] = min(best[name], time.perf_counter() - t0)
        ref = res["cpu"]
        for name, _ in paths:
            r = res[name]
            rows.append(
                dict(
                    n=P.shape[0],
                    path=name,
                    seconds=best[name],
                    ratio=best["cpu"] / best[name],
                    n_iter=r.n_iter,
                    max_diff=float(np.max(np.abs(r.scores - ref.scores))),
                )
            )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--no-torch-cpu", dest="torch_cpu", action="store_false")
    args = ap.parse_args()
    rows = run(args.sizes, args.repeat, args.torch_cpu)
    gpu = "none"
    try:
        import torch

        torch_line = f"torch {torch.__version__}"
        if torch.cuda.is_available():
            gpu = torch.cuda.get_device_name(0)
    except ImportError:
        torch_line = "torch not installed"
    lines = [
        "## GPU path of the patch RPCA (`rpca_scores(device=...)`)",
        "",
        f"Machine: {machine_line()}; {torch_line}; GPU: {gpu}. Dragon clouds with 10 % `mixed` "
        f"outliers, defaults of `rpca_scores`, best of {args.repeat} after a warm-up call.",
        "",
        "| points | path | seconds | points/s | speed-up vs cpu | ALM iterations "
        "| max abs score diff vs cpu (spacings) |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['n']:,} | {r['path']} | {r['seconds']:.2f} | {r['n'] / r['seconds']:,.0f} "
            f"| {r['ratio']:.2f} | {r['n_iter']} | {r['max_diff']:.1e} |"
        )
    lines += ["", "Regenerate: `python benchmarks/bench_gpu_outliers.py`."]
    write_section("bench_gpu_outliers", "\n".join(lines))


if __name__ == "__main__":
    main()
