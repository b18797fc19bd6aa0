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
    """The registration's Eq. 6.42 scores skip the cluster flags; the scores are the same."""
    from spectrageo.outliers import RPCAOptions, rpca_scores
    from spectrageo.register._robust import outlier_scores

    rng = np.random.default_rng(3)
    P = rng.normal(size=(400, 3))
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    P[:8] *= 1.4  # a few points off the sphere
    ref = rpca_scores(P, 10, RPCAOptions(on_nonconvergence="ignore")).scores
    np.testing.assert_array_equal(outlier_scores(P, 10), ref)
