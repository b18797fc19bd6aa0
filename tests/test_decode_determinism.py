"""Decoders give the same coordinates on every machine.

The same ``.sgc`` / ``.sga`` bytes are decoded in fresh processes under every OpenBLAS kernel
this CPU can run (``OPENBLAS_CORETYPE``), with one and two BLAS threads, with numba compiling for
a generic x86-64 CPU instead of this one (no AVX, no FMA), and with numpy's SIMD dispatch turned
off. The decoded arrays must be equal bit for bit: a codec's decoder is deterministic, as an
integer decoder is.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spectrageo import compress
from spectrageo.datasets import fandisk

from conftest import icosphere

_DECODE = r"""
import hashlib, json, sys
from pathlib import Path
import numpy as np
from spectrageo import compress
out = {}
for f in sorted(Path(sys.argv[1]).iterdir()):
    b = f.read_bytes()
    X = compress.decode(b)[0] if f.suffix == ".sgc" else compress.decode_animation(b)[0]
    out[f.name] = hashlib.sha256(np.ascontiguousarray(X, dtype=np.float64).tobytes()).hexdigest()
print(json.dumps(out))
"""


def _cpu_flags() -> set[str]:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:  # pragma: no cover - not Linux
        return set()
    for line in text.splitlines():
        if line.startswith("flags"):
            return set(line.split(":", 1)[1].split())
    return set()  # pragma: no cover


def _core_types() -> list[str]:
    """OpenBLAS kernels this CPU can execute (a kernel for a newer CPU would fault)."""
    flags = _cpu_flags()
    types = ["Prescott"]
    if {"avx2", "fma"} <= flags:
        types.append("Haswell")
    if {"avx512f", "avx512dq", "avx512bw", "avx512vl"} <= flags:
        types.append("SkylakeX")
    return types


def _numpy_dispatched() -> list[str]:
    """numpy's runtime-dispatched SIMD targets that this CPU supports (disabling them all makes
    numpy run its baseline loops, as on an older CPU)."""
    try:
        from numpy._core import _multiarray_umath as mu
    except ImportError:  # pragma: no cover - numpy < 2
        from numpy.core import _multiarray_umath as mu
    return [f for f in mu.__cpu_dispatch__ if mu.__cpu_features__.get(f)]


def _environments() -> list[dict[str, str]]:
    envs = [
        {"OPENBLAS_CORETYPE": ct, "OPENBLAS_NUM_THREADS": str(nt)}
        for ct in _core_types()
        for nt in (1, 2)
    ]
    envs.append({"NUMBA_CPU_NAME": "generic", "OPENBLAS_NUM_THREADS": "2"})
    if _numpy_dispatched():
        envs.append({"NPY_DISABLE_CPU_FEATURES": " ".join(_numpy_dispatched())})
    return envs


def _animation(T: int = 12):
    """A deforming icosphere (T, 642, 3): a travelling bulge and a drift."""
    V, F = icosphere(3)
    t = np.linspace(0, 1, T)[:, None, None]
    frames = V[None] * (1 + 0.2 * np.sin(3 * V[None, :, :1] + 4 * t)) + 0.3 * t
    return frames, F


@pytest.fixture(scope="module")
def coded(tmp_path_factory) -> Path:
    """One file per codec and variant (static on the embedded fandisk, animations on a sphere)."""
    d = tmp_path_factory.mktemp("coded")
    m = fandisk()
    V, F = m.V, m.F
    static = {
        "spectral": {},
        "spectral-exact": {"basis": "exact"},
        "spectral-doi": {"basis": "doi"},
        "spectral-reorder": {"reorder": True},
        "feature": {"method": "feature"},
        "feature-bpv": {"method": "feature", "bpv": 6.0},
        "saliency": {"method": "saliency"},
    }
    for name, kw in static.items():
        kw = dict(kw)
        method = kw.pop("method", "spectral")
        (d / f"{name}.sgc").write_bytes(compress.encode(V, F, method=method, **kw))
    A, Fa = _animation()
    for method in compress.ANIMATION_METHODS:
        opts = {"block": 6} if method == "blocks" else {}
        data = compress.encode_animation(A, Fa, method=method, **opts)
        (d / f"anim-{method}.sga").write_bytes(data)
    data = compress.encode_animation(A, Fa, method="layered", fine=True)
    (d / "anim-layered-fine.sga").write_bytes(data)
    return d


def _decode_in(env: dict[str, str], folder: Path) -> dict[str, str]:
    full = {**os.environ, **env}
    r = subprocess.run(
        [sys.executable, "-c", _DECODE, str(folder)],
        env=full,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, f"decode under {env} failed:\n{r.stderr[-3000:]}"
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_every_codec_decodes_bit_identically_across_blas_kernels_threads_and_cpus(coded):
    files = sorted(p.name for p in coded.iterdir())
    assert len(files) == 7 + len(compress.ANIMATION_METHODS) + 1
    results = {json.dumps(env): _decode_in(env, coded) for env in _environments()}
    first_env, first = next(iter(results.items()))
    assert sorted(first) == files
    differ = {
        name: [env for env, h in results.items() if h[name] != first[name]]
        for name in files
        if any(h[name] != first[name] for h in results.values())
    }
    assert not differ, f"decoded coordinates differ from those under {first_env}: {differ}"


def test_in_process_decode_matches_the_fresh_processes(coded):
    """The decode in this process (warm caches, whatever threads ran before) gives the same
    bytes as a fresh one."""
    fresh = _decode_in({}, coded)
    for f in sorted(coded.iterdir()):
        b = f.read_bytes()
        X = compress.decode(b)[0] if f.suffix == ".sgc" else compress.decode_animation(b)[0]
        h = hashlib.sha256(np.ascontiguousarray(X, dtype=np.float64).tobytes()).hexdigest()
        assert h == fresh[f.name], f.name
