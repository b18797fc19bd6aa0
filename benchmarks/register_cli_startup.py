"""CPU seconds of ``spectrageo register`` through the CLI against a warm in-process call.

Pair: the validation split's real RGB-D fragment pair of ``spectrageo evaluate register``
(``cloud_bin_0`` moved by the split's motion onto ``cloud_bin_1``), written as PLY files. Each
figure is the median (and the minimum) over ``--repeats`` runs of the user + system CPU seconds of
a child process (``getrusage``; load inflates CPU seconds less than wall time, but not nothing):

- ``spectrageo --help``;
- ``spectrageo register SRC TGT --out T.json``;
- a fresh Python process reading both files and calling :func:`spectrageo.register.register`;
- a warm call: the second read + ``register()`` in one process (its CPU seconds only);
- the floor of any process on the register path: importing numpy and scipy.spatial; and, for
  comparison, the floor of the path before the robustification's RPCA ran on NumPy (Eq. 6.42;
  docs/decisions.md#register-numpy-rpca): also numba and one first call of a cached numba kernel.

The CLI overhead is the CLI's figure minus the warm call's; the poses of all runs are compared
(they must be identical). ``--baseline DIR`` measures another version's ``src`` folder too
(``PYTHONPATH``), alternating with this tree's runs so that both see the same load.

    python benchmarks/register_cli_startup.py [--repeats 5] [--baseline /tmp/old/src]

Writes ``benchmarks/_out/register_cli_startup.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, write_section  # noqa: E402

_API = (
    "import json, sys\n"
    "from spectrageo import io\n"
    "from spectrageo.register import register\n"
    "r = register(io.read(sys.argv[1]), io.read(sys.argv[2]), rng=0)\n"
    "print(json.dumps(r.transformation.tolist()))\n"
)


_WARM = (
    "import json, resource, sys\n"
    "from spectrageo import io\n"
    "from spectrageo.register import register\n"
    "def call():\n"
    "    return register(io.read(sys.argv[1]), io.read(sys.argv[2]), rng=0)\n"
    "call()\n"
    "r0 = resource.getrusage(resource.RUSAGE_SELF)\n"
    "res = call()\n"
    "r1 = resource.getrusage(resource.RUSAGE_SELF)\n"
    "cpu = r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime\n"
    "print(json.dumps([cpu, res.transformation.tolist()]))\n"
)


#: what any process running the register path pays before spectrageo's own work: numpy and
#: scipy.spatial (cKDTree); with numba and numba's first call of a cached kernel, the floor of the
#: path while the robustification's RPCA (Eq. 6.42) ran numba kernels
_FLOOR = {
    "floor: import numpy, scipy.spatial": "import numpy, scipy.spatial",
    "numba floor: ... + numba + first cached kernel call": (
        "import numpy, scipy.spatial, numba\n"
        "from spectrageo.outliers._common import morton_codes\n"
        "morton_codes(numpy.random.default_rng(0).random((10, 3)))\n"
    ),
}


def _child_cpu(cmd: list[str], env: dict[str, str]) -> tuple[float, str]:
    """(user + system CPU seconds of the finished child ``cmd``, its stdout)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, proc.stdout


def _measure(tree: dict, src: Path, tgt: Path, out: Path, runs: dict, poses: dict) -> None:
    """One run of each measurement with the package of ``tree`` (``env``: its environment)."""
    exe, env, key = tree["exe"], tree["env"], tree["name"]
    runs[key, "help"].append(_child_cpu([exe, "--help"], env)[0])
    cmd = [exe, "register", str(src), str(tgt), "--out", str(out), "-q"]
    runs[key, "cli"].append(_child_cpu(cmd, env)[0])
    poses[key, "cli"] = np.array(json.loads(out.read_text())["transformation"])
    cpu, text = _child_cpu([sys.executable, "-c", _API, str(src), str(tgt)], env)
    runs[key, "api"].append(cpu)
    poses[key, "api"] = np.array(json.loads(text.strip().splitlines()[-1]))
    _, text = _child_cpu([sys.executable, "-c", _WARM, str(src), str(tgt)], env)
    cpu, T = json.loads(text.strip().splitlines()[-1])
    runs[key, "warm"].append(cpu)
    poses[key, "warm"] = np.array(T)
    for label, code in _FLOOR.items():
        runs[key, label].append(_child_cpu([sys.executable, "-c", code], env)[0])


def write_pair(folder: Path) -> tuple[Path, Path]:
    """The validation fragment pair as ``src.ply``, ``tgt.ply`` in ``folder``."""
    from spectrageo import io
    from spectrageo.datasets import data_dir
    from spectrageo.evaluate import register as ev
    from spectrageo.geometry import PointCloud

    pair = ev.fragment_pairs(Path(data_dir(required=True)), ev.VALIDATION["bunny_seed"])[0]
    src, tgt = folder / "src.ply", folder / "tgt.ply"
    io.write(src, PointCloud(points=pair["source"]))
    io.write(tgt, PointCloud(points=pair["target"]))
    return src, tgt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument(
        "--baseline",
        default=None,
        help="a copy of another version's src folder, measured in the same run, alternating",
    )
    args = ap.parse_args()
    exe = str(Path(sys.executable).parent / "spectrageo")
    trees = [{"name": "this tree", "exe": exe, "env": dict(os.environ)}]
    if args.baseline:
        env = {**os.environ, "PYTHONPATH": str(Path(args.baseline).resolve())}
        trees.insert(0, {"name": "baseline", "exe": exe, "env": env})
    runs: dict = defaultdict(list)
    poses: dict = {}
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        src, tgt = write_pair(folder)
        out = folder / "T.json"
        for tree in trees:  # untimed: numba caches of each tree
            _child_cpu(
                [tree["exe"], "register", str(src), str(tgt), "--out", str(out)], tree["env"]
            )
        for _ in range(args.repeats):
            for tree in trees:
                _measure(tree, src, tgt, out, runs, poses)
    load = (load0, os.getloadavg())
    med = {k: float(np.median(v)) for k, v in runs.items()}
    lines = [
        "## Start-up cost of `spectrageo register` (CPU seconds)",
        "",
        f"Machine: {machine_line()}. Pair: validation real RGB-D fragment pair "
        f"(cloud_bin_0 moved -> cloud_bin_1). Median of {args.repeats} runs, user + system. "
        f"Load average (1, 5, 15 min) at the start {' '.join(f'{x:.1f}' for x in load[0])}, "
        f"at the end {' '.join(f'{x:.1f}' for x in load[1])}.",
        "",
        "| tree | run | CPU s (median) | min | all runs |",
        "|---|---|---:|---:|---|",
    ]
    names = {
        "help": "`spectrageo --help`",
        "cli": "`spectrageo register SRC TGT`",
        "api": "fresh `python -c` API call",
        "warm": "warm read + `register()` (second call in one process)",
        **{k: k for k in _FLOOR},
    }
    for tree in trees:
        for k, label in names.items():
            v = runs[tree["name"], k]
            lines.append(
                f"| {tree['name']} | {label} | {med[tree['name'], k]:.2f} | {min(v):.2f} | "
                f"{' '.join(f'{x:.2f}' for x in v)} |"
            )
    lines.append("")
    ref = poses[trees[0]["name"], "warm"]
    for tree in trees:
        key = tree["name"]
        same = all(np.array_equal(ref, poses[key, k]) for k in ("cli", "api", "warm"))
        diff = max(float(np.abs(ref - poses[key, k]).max()) for k in ("cli", "api", "warm"))
        lines.append(
            f"- {key}: CLI overhead over the warm call {med[key, 'cli'] - med[key, 'warm']:.2f} s "
            f"(medians; minima: {min(runs[key, 'cli']) - min(runs[key, 'warm']):.2f} s; target "
            f"<= 1 s); poses identical to {trees[0]['name']}'s warm call: {same} (largest "
            f"entry difference {diff:.1e})."
        )
    text = "\n".join(lines)
    print(text)
    write_section("register_cli_startup", text)


if __name__ == "__main__":
    main()
