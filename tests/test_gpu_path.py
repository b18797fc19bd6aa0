"""The PyTorch path of the patch RPCA (issue 21) against the numba path; device selection.

Without a GPU the torch path runs on ``torch.device("cpu")``: it is the same code as on CUDA, so
it checks the iteration (mu schedule, stopping rules, SVT, precision) against the numba kernel.
The tests that need CUDA are skipped when ``torch.cuda.is_available()`` is False.

Tolerance (stated in :func:`spectrageo.outliers.rpca_scores`): the scores of the two paths differ
by at most ``TOL = 1e-3`` spacings (measured on the shared bunny scan, clean and with 10 %
injected outliers: ``5e-5`` in float32, ``3e-8`` in float64; ``2e-4`` on 1.1M points), and
keep masks agree except for points whose score lies within ``TOL`` of the threshold.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from spectrageo import PointCloud, io, noise
from spectrageo import _device as devmod
from spectrageo._device import resolve_backend, resolve_device
from spectrageo._errors import InvalidInputError
from spectrageo.cli.main import main
from spectrageo.outliers import RPCAOptions, detect_outliers, remove_outliers, rpca_scores

from conftest import shared_file

torch = pytest.importorskip("torch", reason="torch is not installed: the GPU path needs it")

#: Largest |score difference| (spacings) between the torch and the numba path (float32 state).
TOL = 1e-3
#: The same in float64.
TOL64 = 1e-6
HAS_CUDA = bool(torch.cuda.is_available())
needs_cuda = pytest.mark.skipif(not HAS_CUDA, reason="no CUDA GPU visible to torch")
TORCH_CPU = torch.device("cpu")


@pytest.fixture(scope="module")
def bunny(shared_data):
    path = shared_file(shared_data, "scans", "bunny", "bun000.ply.gz")
    return np.asarray(io.read(path).points)


def _sheet(n=3000, seed=0):
    """A wavy sheet with mixed outliers (small, synthetic)."""
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2))
    P = np.column_stack([xy, 0.1 * np.sin(6 * xy[:, 0]) * np.cos(4 * xy[:, 1])])
    P[:, 2] += 0.002 * rng.standard_normal(n)
    Q, _ = noise.corrupt_outliers(P, pattern="mixed", fraction=0.1, rng=seed)
    return Q


def _check_masks(a, b, tol):
    """Keep masks equal except for points within ``tol`` of the threshold."""
    assert abs(a.threshold - b.threshold) <= tol
    differ = a.keep != b.keep
    near = np.abs(a.scores - a.threshold) <= tol
    assert not np.any(differ & ~near)


# --------------------------------------------------------------------------- resolve_device
def test_resolve_device_cpu_and_auto():
    assert resolve_device("cpu") == "cpu"
    assert resolve_device(" CPU ") == "cpu"
    assert resolve_device("auto") == ("cuda" if HAS_CUDA else "cpu")
    assert resolve_backend("cpu") == "cpu"
    assert resolve_backend(TORCH_CPU) == TORCH_CPU


@pytest.mark.parametrize("bad", ["gpu", "cuda:x", "", 3, None])
def test_resolve_device_rejects_unknown(bad):
    with pytest.raises(InvalidInputError, match="`device` must be one of"):
        resolve_device(bad)


def test_resolve_backend_rejects_other_torch_devices():
    with pytest.raises(InvalidInputError, match="CPU or CUDA torch.device"):
        resolve_backend(torch.device("meta"))
    with pytest.raises(InvalidInputError, match="`device` must be one of"):
        resolve_backend(1.5)


@pytest.mark.skipif(HAS_CUDA, reason="a CUDA GPU is visible")
def test_resolve_device_cuda_without_gpu():
    with pytest.raises(InvalidInputError, match="no CUDA GPU is available"):
        resolve_device("cuda")
    with pytest.raises(InvalidInputError, match="no CUDA GPU is available"):
        resolve_backend(torch.device("cuda"))


def test_resolve_device_without_torch(monkeypatch):
    monkeypatch.setattr(devmod, "_import_torch", lambda: None)
    assert resolve_device("cpu") == "cpu"
    assert resolve_device("auto") == "cpu"
    with pytest.raises(InvalidInputError, match="torch is not installed"):
        resolve_device("cuda")


def test_cpu_path_needs_no_torch():
    """A plain install without torch: device 'cpu' and 'auto' work and never import torch."""
    code = (
        "import sys; sys.modules['torch'] = None\n"
        "import numpy as np\n"
        "from spectrageo._device import resolve_device\n"
        "from spectrageo.outliers import RPCAOptions, rpca_scores\n"
        "assert resolve_device('auto') == 'cpu'\n"
        "P = np.random.default_rng(0).random((300, 3))\n"
        "r = rpca_scores(P, options=RPCAOptions(refine=False, clusters=False), device='auto')\n"
        "assert np.isfinite(r.scores).all()\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


# --------------------------------------------------------------------------- API wiring
def test_rpca_scores_rejects_bad_device():
    P = _sheet(300)
    with pytest.raises(InvalidInputError, match="`device` must be one of"):
        rpca_scores(P, device="gpu")


@pytest.mark.parametrize("method", ["sor", "radius"])
def test_other_methods_run_on_cpu_only(method):
    P = _sheet(500)
    ref = remove_outliers(P, method=method)
    auto = remove_outliers(P, method=method, device="auto")
    np.testing.assert_array_equal(ref.keep, auto.keep)
    with pytest.raises(InvalidInputError, match="applies to method='rpca' only"):
        remove_outliers(P, method=method, device="cuda")


# --------------------------------------------------------------------------- torch vs numba
@pytest.mark.parametrize("pattern", [None, "uniform", "halo"])
def test_torch_path_matches_numba_on_bunny(bunny, pattern):
    P = bunny if pattern is None else noise.corrupt_outliers(bunny, pattern=pattern, rng=0)[0]
    a = detect_outliers(P, workers=1)
    b = detect_outliers(P, workers=1, device=TORCH_CPU)
    assert np.max(np.abs(a.scores - b.scores)) <= TOL
    assert a.info["n_iter"] == b.info["n_iter"]
    assert a.info["n_refined"] == b.info["n_refined"]
    assert a.info["n_cluster_outliers"] == b.info["n_cluster_outliers"]
    _check_masks(a, b, TOL)


@pytest.mark.parametrize(
    "opts, tol",
    [
        (dict(smoothed=True, options=RPCAOptions(block_size=1000)), TOL),
        (dict(options=RPCAOptions(dtype="float64", rank_tol=0.0)), TOL64),
        (dict(options=RPCAOptions(refine=False, tangent_weight=1.0)), TOL),
    ],
)
def test_torch_path_matches_numba_options(opts, tol):
    P = _sheet()
    a = rpca_scores(P, workers=1, **opts)
    b = rpca_scores(P, workers=1, device=TORCH_CPU, **opts)
    assert np.max(np.abs(a.scores - b.scores)) <= tol
    assert (a.n_iter, a.n_blocks, a.n_refined) == (b.n_iter, b.n_blocks, b.n_refined)
    assert a.converged == b.converged
    assert b.residual == pytest.approx(a.residual, rel=1e-3)
    if opts.get("smoothed"):
        assert np.max(np.abs(a.smoothed - b.smoothed)) <= tol * a.spacing


def test_torch_path_degenerate_line():
    """Collinear points (rank-1 patches): both paths agree."""
    t = np.random.default_rng(0).random(200)
    P = np.column_stack([t, 2 * t, -t])
    opts = RPCAOptions(refine=False, clusters=False)
    a = rpca_scores(P, options=opts, workers=1)
    b = rpca_scores(P, options=opts, workers=1, device=TORCH_CPU)
    assert np.max(np.abs(a.scores - b.scores)) <= TOL


def test_torch_path_with_duplicate_points():
    """Exact duplicates are scored once per position on both paths (the device is passed on)."""
    P = _sheet(800)
    P = np.concatenate([P, P[:50]])
    a = rpca_scores(P, workers=1)
    b = rpca_scores(P, workers=1, device=TORCH_CPU)
    assert np.max(np.abs(a.scores - b.scores)) <= TOL
    np.testing.assert_array_equal(b.scores[-50:], b.scores[:50])


# --------------------------------------------------------------------------- CLI
@pytest.fixture
def sheet_file(tmp_path):
    path = tmp_path / "sheet.ply"
    io.write(path, PointCloud(_sheet(600)))
    return path


def test_cli_device_cpu_and_auto(capsys, tmp_path, sheet_file):
    masks = []
    for dev in ("cpu", "auto"):
        mask = tmp_path / f"keep_{dev}.npy"
        code = main(
            [
                "outliers",
                str(sheet_file),
                str(tmp_path / f"out_{dev}.ply"),
                "--device",
                dev,
                "--mask",
                str(mask),
            ]
        )
        capsys.readouterr()
        assert code == 0
        masks.append(np.load(mask))
    if not HAS_CUDA:
        np.testing.assert_array_equal(masks[0], masks[1])


@pytest.mark.skipif(HAS_CUDA, reason="a CUDA GPU is visible")
def test_cli_device_cuda_without_gpu(capsys, tmp_path, sheet_file):
    out = tmp_path / "out.ply"
    code = main(["outliers", str(sheet_file), str(out), "--device", "cuda"])
    _, err = capsys.readouterr()
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1
    assert "no CUDA GPU" in lines[0]
    assert "Traceback" not in err
    assert not out.exists()


def test_cli_device_rejects_unknown(capsys, tmp_path, sheet_file):
    with pytest.raises(SystemExit) as exc:  # argparse: usage line and the error, exit 2
        main(["outliers", str(sheet_file), str(tmp_path / "o.ply"), "--device", "gpu"])
    _, err = capsys.readouterr()
    assert exc.value.code == 2
    assert "--device" in err


def test_cli_device_cuda_refused_for_sor_tiles_and_sequences(capsys, tmp_path, sheet_file):
    """--device cuda where no GPU path exists: one clear line, exit 2, nothing written."""
    from spectrageo.geometry import PointCloudSequence

    out = tmp_path / "o.ply"
    code = main(["outliers", str(sheet_file), str(out), "--tile", "300", "--method", "sor",
                 "--device", "cuda"])  # fmt: skip
    _, err = capsys.readouterr()
    assert code == 2 and "--method rpca only" in err and "Traceback" not in err
    assert not out.exists()
    seq = tmp_path / "seq.npz"
    io.write(seq, PointCloudSequence([_sheet(300), _sheet(300) + 0.01]))
    code = main(["outliers", str(seq), str(tmp_path / "s.npz"), "--device", "cuda"])
    _, err = capsys.readouterr()
    assert code == 2 and "sequences are cleaned on the CPU" in err
    assert not (tmp_path / "s.npz").exists()


@pytest.mark.skipif(HAS_CUDA, reason="a CUDA GPU is visible")
def test_cli_tiles_pass_the_device_on(capsys, tmp_path, sheet_file):
    """--tile with --device auto runs every tile's RPCA there (the CPU here): same mask as cpu."""
    pytest.importorskip("distributed")
    masks = []
    for dev in ("cpu", "auto"):
        mask = tmp_path / f"k_{dev}.npy"
        code = main(["outliers", str(sheet_file), str(tmp_path / f"t_{dev}.ply"), "--tile", "300",
                     "--workers", "1", "--device", dev, "--mask", str(mask), "-q"])  # fmt: skip
        capsys.readouterr()
        assert code == 0
        masks.append(np.load(mask))
    np.testing.assert_array_equal(masks[0], masks[1])
    code = main(["outliers", str(sheet_file), str(tmp_path / "t_cuda.ply"), "--tile", "300",
                 "--workers", "1", "--device", "cuda", "-q"])  # fmt: skip
    _, err = capsys.readouterr()
    assert code == 2 and "no CUDA GPU" in err
    assert not (tmp_path / "t_cuda.ply").exists()


# --------------------------------------------------------------------------- CUDA
@needs_cuda
def test_resolve_device_cuda():
    assert resolve_device("cuda") == "cuda"
    assert resolve_device("auto") == "cuda"
    assert resolve_device("cuda:0") == "cuda:0"


@needs_cuda
@pytest.mark.parametrize("pattern", [None, "uniform"])
def test_cuda_matches_cpu_on_bunny(bunny, pattern):
    P = bunny if pattern is None else noise.corrupt_outliers(bunny, pattern=pattern, rng=0)[0]
    a = detect_outliers(P)
    b = detect_outliers(P, device="cuda")
    assert np.max(np.abs(a.scores - b.scores)) <= TOL
    assert a.info["n_iter"] == b.info["n_iter"]
    _check_masks(a, b, TOL)


@needs_cuda
def test_cuda_matches_cpu_options():
    P = _sheet()
    opts = dict(smoothed=True, options=RPCAOptions(block_size=1000))
    a = rpca_scores(P, **opts)
    b = rpca_scores(P, device="cuda", **opts)
    assert np.max(np.abs(a.scores - b.scores)) <= TOL
    assert np.max(np.abs(a.smoothed - b.smoothed)) <= TOL * a.spacing
    exact = RPCAOptions(dtype="float64", rank_tol=0.0)
    c = rpca_scores(P, options=exact)
    d = rpca_scores(P, options=exact, device="cuda")
    assert np.max(np.abs(c.scores - d.scores)) <= TOL64
