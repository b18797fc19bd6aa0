"""What a command imports before it runs: the packages it needs and no others (start-up time).

Each check runs in a fresh interpreter and reads ``sys.modules``; none measures time.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

#: heavy dependencies that only the solvers need
HEAVY = ("scipy", "numba", "llvmlite", "sklearn", "trimesh", "torch", "open3d")
#: packages of other commands
OTHERS = (
    "spectrageo.denoise",
    "spectrageo.compress",
    "spectrageo.learn",
    "spectrageo.saliency",
    "spectrageo.outliers",
    "spectrageo.register",
    "spectrageo.evaluate",
    "spectrageo.datasets",
)


def _loaded(code: str, watch: tuple[str, ...]) -> list[str]:
    """The modules of ``watch`` (or their submodules) that ``code`` leaves in ``sys.modules``."""
    probe = textwrap.dedent(code) + textwrap.dedent(
        f"""
        import json, sys
        watch = {watch!r}
        print(json.dumps(sorted(w for w in watch
                                if any(m == w or m.startswith(w + ".") for m in sys.modules))))
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=120
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_top_level_help_imports_no_solver_and_no_other_package():
    code = """
        import contextlib, io
        from spectrageo.cli.main import main
        with contextlib.redirect_stdout(io.StringIO()):
            try:
                main(["--help"])
            except SystemExit:
                pass
    """
    assert _loaded(code, HEAVY + OTHERS) == []


def test_parsing_register_imports_no_solver():
    code = """
        from spectrageo.cli.main import build_parser
        p = build_parser("register")
        p.parse_args(["register", "a.ply", "b.ply", "--out", "T.json"])
    """
    assert _loaded(code, HEAVY + OTHERS) == []


def test_package_and_reading_a_point_cloud_import_no_solver(tmp_path):
    from spectrageo import io
    from spectrageo.geometry import PointCloud

    path = tmp_path / "p.ply"
    io.write(path, PointCloud(points=np.random.default_rng(0).random((20, 3))))
    code = f"""
        import spectrageo
        from spectrageo import io
        io.read({str(path)!r})
    """
    assert _loaded(code, HEAVY + OTHERS) == []


def test_top_level_help_equals_the_full_parsers():
    from spectrageo.cli import main as cli_main

    full = cli_main.build_parser().format_help()
    assert cli_main.build_parser(summary=True).format_help() == full


def test_lazy_package_names_resolve():
    import spectrageo
    import spectrageo.linalg.rpca  # the submodule first: the name must stay the function
    from spectrageo import geometry, linalg, register

    for pkg in (geometry, linalg, register):
        assert dir(pkg) == sorted(pkg.__all__)
        for name in pkg.__all__:
            assert getattr(pkg, name) is not None, (pkg.__name__, name)
        with pytest.raises(AttributeError):
            pkg.no_such_name  # noqa: B018
    assert callable(linalg.rpca) and callable(linalg.lasso)
    assert geometry.knn.__module__ == "spectrageo.geometry.neighbors"
    assert spectrageo.Mesh is geometry.Mesh


def test_register_outlier_scores_equal_rpca_scores():
    """The registration's Eq. 6.42 scores skip the cluster flags and run on the NumPy backend;
    the scores equal the default (numba) ones within rounding."""
    from spectrageo.outliers import RPCAOptions, rpca_scores
    from spectrageo.register._robust import outlier_scores

    rng = np.random.default_rng(3)
    P = rng.normal(size=(400, 3))
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    P[:8] *= 1.4  # a few points off the sphere
    ref = rpca_scores(P, 10, RPCAOptions(on_nonconvergence="ignore")).scores
    np.testing.assert_allclose(outlier_scores(P, 10), ref, rtol=0, atol=1e-4)


def test_register_command_imports_no_numba(tmp_path):
    """``spectrageo register`` on small PLY files runs the robustification (Eq. 6.42) without
    loading numba (docs/decisions.md#register-numpy-rpca)."""
    from spectrageo import io
    from spectrageo.geometry import PointCloud

    rng = np.random.default_rng(0)
    u, v = rng.random((2, 1500))
    P = np.column_stack([u, v, 0.2 * np.sin(3 * u) * np.cos(2 * v)])
    c, s = np.cos(0.1), np.sin(0.1)
    Q = P @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + 0.01
    io.write(tmp_path / "a.ply", PointCloud(points=P))
    io.write(tmp_path / "b.ply", PointCloud(points=Q))
    code = f"""
        from spectrageo.cli.main import main
        main(["register", {str(tmp_path / "a.ply")!r}, {str(tmp_path / "b.ply")!r},
              "--out", {str(tmp_path / "T.json")!r}, "-q"])
    """
    assert _loaded(code, ("numba", "llvmlite", "sklearn", "torch", "open3d")) == []
    T = np.array(json.loads((tmp_path / "T.json").read_text())["transformation"])
    assert T.shape == (4, 4)
