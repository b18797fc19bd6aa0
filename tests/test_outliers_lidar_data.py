"""The airborne LiDAR tuning scans shipped in ``benchmarks/data/lidar`` (``Case.root == "repo"``):
registered as tuning, resolved by the scan-type benchmark, skipped with a notice when absent."""

from __future__ import annotations

import hashlib

import numpy as np

from spectrageo.datasets import splits as S
from spectrageo.datasets._split_outliers import OUTLIER_SCAN_TYPES, OUTLIER_SCAN_TYPES_IN_REPO

#: sha256 prefixes of the files as copied from PDAL (benchmarks/data/lidar/README.md)
_SHA = {
    "lidar/pdal_4_6_crop.las": "c432b44d4e938ed3",
    "lidar/pdal_hexbin_crop.las": "d1206c580a8c9c56",
    "lidar/pdal_warsaw_small.las": "e416058a79306c5a",
    "lidar/pdal_mvk_thin.las": "c3707f90cc153b4a",
}


def test_repo_scans_are_lidar_tuning_cases():
    cases = [c for c in S.cases("outliers-scantypes") if c.root == "repo"]
    assert {c.file for c in cases} == set(OUTLIER_SCAN_TYPES_IN_REPO) == set(_SHA)
    for c in cases:
        assert c.split == "tuning" and not c.consulted_by
        assert OUTLIER_SCAN_TYPES[c.file] == ("LiDAR", None)
        assert c.name == f"LiDAR: {c.file.rsplit('/', 1)[-1].removesuffix('.las')}"
    assert S.split_of("outliers-scantypes", "LiDAR: pdal_4_6_crop") == "tuning"


def test_repo_scans_are_in_the_source_tree():
    from spectrageo.evaluate._outliers_scans import REPO_DATA, scan_path

    assert (REPO_DATA / "lidar" / "LICENSE_pdal").is_file()
    assert (REPO_DATA / "lidar" / "README.md").is_file()
    for rel, sha in _SHA.items():
        p = scan_path(REPO_DATA.parent / "elsewhere", rel)
        assert p == REPO_DATA / rel and p.is_file()
        assert hashlib.sha256(p.read_bytes()).hexdigest().startswith(sha)
    # shared-data cases resolve against the given data folder
    assert scan_path(REPO_DATA, "scans/pcl/milk.pcd") == REPO_DATA / "scans/pcl/milk.pcd"


def test_scan_types_read_a_repo_scan(tmp_path, monkeypatch):
    """A repo case runs with any data folder (here an empty one): clean, injected, bands rows."""
    from spectrageo import io
    from spectrageo.evaluate import _outliers_scans as ev

    case = next(c for c in ev.SCAN_TYPE_CASES if c[1] == "lidar/pdal_4_6_crop.las")
    pc = io.read(ev.scan_path(tmp_path, case[1]), kind="points")
    assert pc.points.shape == (23875, 3)
    P = pc.points[np.argsort(pc.points[:, 0], kind="stable")[:3000]]  # a strip: a short run
    monkeypatch.setattr(ev, "SCAN_TYPE_CASES", (case,))
    monkeypatch.setattr(ev, "INJECTED_FRACTIONS", (0.1,))
    monkeypatch.setattr(io, "read", _reader(pc, P))
    rows = ev.evaluate_scan_types(tmp_path, splits=("tuning",))
    assert {r["kind"] for r in rows} == {"clean", "injected", "bands"}
    assert {r["scan_type"] for r in rows} == {"LiDAR"} and {r["split"] for r in rows} == {"tuning"}
    assert all(r["n_points"] >= 3000 for r in rows)


def _reader(pc, P):
    from spectrageo.geometry import PointCloud

    def read(path, **kw):
        assert str(path).endswith("pdal_4_6_crop.las")
        return PointCloud(P)

    return read


def test_scan_types_skip_an_absent_repo_scan(tmp_path, monkeypatch, capsys):
    from spectrageo.evaluate import _outliers_scans as ev

    case = next(c for c in ev.SCAN_TYPE_CASES if c[1] == "lidar/pdal_hexbin_crop.las")
    milk = next(c for c in ev.SCAN_TYPE_CASES if c[1] == "scans/pcl/milk.pcd")
    monkeypatch.setattr(ev, "SCAN_TYPE_CASES", (case,))
    monkeypatch.setattr(ev, "REPO_DATA", tmp_path / "no-benchmarks-data")
    assert ev.evaluate_scan_types(tmp_path) == []
    assert "LiDAR: pdal_hexbin_crop skipped" in capsys.readouterr().out
    # a shared-data case absent from the data folder is skipped silently, as before
    monkeypatch.setattr(ev, "SCAN_TYPE_CASES", (milk,))
    assert ev.evaluate_scan_types(tmp_path) == []
    assert capsys.readouterr().out == ""
