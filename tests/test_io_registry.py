"""io's format registry: built-in formats, and formats of higher layers registered as plugins."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from spectrageo import InvalidInputError, UnsupportedFormatError, io
from spectrageo.geometry.data import Mesh

from conftest import icosphere

_FRESH = r"""
import sys
from spectrageo import io
assert "spectrageo.compress" not in sys.modules, "io imported compress"
m = io.read(sys.argv[1])
assert "spectrageo.compress" in sys.modules
print(type(m).__name__, m.n_vertices)
"""


def test_io_never_imports_compress_but_reads_its_files(tmp_path):
    from spectrageo import compress

    V, F = icosphere(2)
    path = tmp_path / "m.sgc"
    path.write_bytes(compress.encode(V, F))
    r = subprocess.run(
        [sys.executable, "-c", _FRESH, str(path)], capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == ["Mesh", str(len(V))]


def test_plugin_formats_are_listed_in_order():
    read = io.supported_formats()["read"]
    assert read[-4:] == [".sgc", ".npz", ".sga", "<folder>/"]
    assert read.index(".3mf") == read.index(".sgc") - 1


def test_write_of_a_plugin_format_gives_its_advice(tmp_path):
    V, F = icosphere(1)
    with pytest.raises(UnsupportedFormatError, match="written by `spectrageo compress`"):
        io.write(tmp_path / "m.sgc", Mesh(V, F))
    assert not list(tmp_path.iterdir())


def test_register_format_refuses_builtin_and_malformed_suffixes():
    def reader(data, name):  # pragma: no cover - never called
        raise AssertionError

    with pytest.raises(InvalidInputError, match="built-in"):
        io.register_format(".ply", reader)
    with pytest.raises(InvalidInputError, match="lower-case extension"):
        io.register_format("SGC", reader)


def test_a_registered_reader_is_used(tmp_path):
    from spectrageo.io._api import _PLUGINS, _WRITE_ADVICE
    from spectrageo.io._raw import RawGeometry

    def reader(data, name):
        pts = np.frombuffer(data, dtype="<f8").reshape(-1, 3)
        return RawGeometry(vertices=pts.copy())

    io.register_format(".tst", reader, write_advice="read only")
    try:
        (tmp_path / "p.tst").write_bytes(np.arange(6.0).tobytes())
        pc = io.read(tmp_path / "p.tst")
        np.testing.assert_array_equal(pc.points, np.arange(6.0).reshape(2, 3))
        with pytest.raises(UnsupportedFormatError, match="read only"):
            io.write(tmp_path / "q.tst", pc)
    finally:
        _PLUGINS.pop(".tst", None)
        _WRITE_ADVICE.pop(".tst", None)
