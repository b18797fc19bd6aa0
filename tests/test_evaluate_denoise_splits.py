"""The generality protocol of `spectrageo evaluate denoise --split` (issue 14): fixed, disjoint
tuning / validation splits, peers at their fixed setting and per-case oracle, and the report."""

import csv
import re
from pathlib import Path

import numpy as np
import pytest

from spectrageo._errors import InvalidInputError
from spectrageo.evaluate import denoise as ev
from spectrageo.evaluate.denoise import (
    GRID_COLUMNS,
    LEFT_OUT,
    PEER_FIXED,
    PEER_GRIDS,
    PROTOCOL_COLUMNS,
    SAME_SHAPE_AS_TUNING,
    TUNING_MESHES,
    TUNING_PAIRS,
    VALIDATION_MESHES,
    choose_fixed,
    evaluate_generality,
    peer_rows,
    protocol_cases,
    setting_label,
)

from conftest import in_ci, require_module, skip_or_fail

MESH_SUFFIXES = (".off", ".obj", ".ply", ".stl", ".gz")


def _shape(name: str) -> str:
    """A model's shape name: file stem or pair name without the noise level, lower case."""
    stem = Path(name).name.lower()
    for suf in MESH_SUFFIXES:
        stem = stem.removesuffix(suf)
    stem = stem.removesuffix(".ply")
    return re.sub(r"(n?\d+(\.\d+)?)?(impulsive)?$", "", stem)


def test_splits_are_disjoint_by_file_and_by_shape():
    assert not set(TUNING_MESHES) & set(VALIDATION_MESHES)
    assert not set(SAME_SHAPE_AS_TUNING) & set(VALIDATION_MESHES)
    assert not set(LEFT_OUT) & set(VALIDATION_MESHES)
    tuning_shapes = {_shape(p) for p in TUNING_PAIRS} | {_shape(m) for m in TUNING_MESHES}
    assert {"block", "fandisk", "bunny", "casting", "spot"} <= tuning_shapes
    validation_shapes = {_shape(m) for m in VALIDATION_MESHES}
    assert not tuning_shapes & validation_shapes
    # the same-shape exclusions really are tuning shapes (bunny: the pair is "Bunny0.2")
    for m in SAME_SHAPE_AS_TUNING:
        assert any(s in _shape(m) for s in tuning_shapes), m
    cases = protocol_cases("both")
    tun = {c.model for c in cases if c.split == "tuning"}
    val = {c.model for c in cases if c.split == "validation"}
    assert tun == set(TUNING_PAIRS) | set(TUNING_MESHES)
    assert val == set(VALIDATION_MESHES) and not tun & val
    names = [c.name for c in cases]
    assert len(names) == len(set(names))
    # 5 kinds x 3 levels per generated model, the pairs once
    assert len(cases) == len(TUNING_PAIRS) + 15 * (len(TUNING_MESHES) + len(VALIDATION_MESHES))
    assert [c.split for c in protocol_cases("tuning")] == ["tuning"] * (
        len(TUNING_PAIRS) + 15 * len(TUNING_MESHES)
    )


def test_case_seeds_depend_on_the_case_only():
    a = {c.name: c.seed for c in protocol_cases("validation", levels=[0.3])}
    b = {c.name: c.seed for c in protocol_cases("both", levels=[0.1, 0.3], kinds=None)}
    assert all(b[k] == v for k, v in a.items())
    assert len(set(a.values())) == len(a)
    c = {x.name: x.seed for x in protocol_cases("validation", levels=[0.3], seed=1)}
    assert all(c[k] != v for k, v in a.items())


def test_split_files_exist_and_cover_the_shared_clean_meshes(shared_data):
    from spectrageo import io

    for rel in (*TUNING_MESHES, *VALIDATION_MESHES, *SAME_SHAPE_AS_TUNING, *LEFT_OUT):
        assert (shared_data / rel).is_file(), rel
    pairs = {p.name for p in (shared_data / "denoise").iterdir() if (p / "Noisy.obj").exists()}
    assert pairs == set(TUNING_PAIRS)
    # every clean mesh of meshes/ and cad/ is placed: tuning, validation, same shape, left out
    placed = set(TUNING_MESHES) | set(VALIDATION_MESHES) | set(SAME_SHAPE_AS_TUNING)
    placed |= set(LEFT_OUT)
    for folder in ("meshes", "cad"):
        for p in (shared_data / folder).iterdir():
            if p.name.lower().endswith(MESH_SUFFIXES):
                assert f"{folder}/{p.name}" in placed, p.name
    # validation holds every CAD tessellation and a mesh of more than 100k vertices
    cad = {f"cad/{p.name}" for p in (shared_data / "cad").iterdir()}
    cad = {c for c in cad if c.lower().endswith(MESH_SUFFIXES)}
    assert cad and cad <= set(VALIDATION_MESHES)
    sizes = {m: io.read_mesh(shared_data / m).vertices.shape[0] for m in VALIDATION_MESHES}
    assert max(sizes.values()) >= 100_000
    assert min(sizes.values()) >= 200


def test_fixed_settings_are_grid_points_and_labels_unique():
    assert set(PEER_FIXED) == set(PEER_GRIDS)
    for peer, grid in PEER_GRIDS.items():
        labels = [setting_label(p) for p in grid]
        assert len(labels) == len(set(labels)), peer
        assert PEER_FIXED[peer] in grid, peer
    assert setting_label({"stepsmoothnum": 3, "normalthr": 60.0}) == "iter=3 thr=60"


def _grid(case, peer, thetas, errors=()):
    return [
        {
            "split": "tuning",
            "case": case,
            "method": peer,
            "setting": setting_label(p),
            "theta_deg": t,
            "time_s": 0.1,
            "error": "boom" if i in errors else "",
        }
        for i, (p, t) in enumerate(zip(PEER_GRIDS[peer], thetas))
    ]


def test_choose_fixed_takes_the_lowest_mean_over_the_given_cases():
    peer = "open3d-taubin"
    k = len(PEER_GRIDS[peer])
    a = np.linspace(10, 20, k)
    b = np.linspace(20, 5, k)  # case b alone would choose the last point
    grid = _grid("a", peer, a) + _grid("b", peer, b) + _grid("c", peer, np.full(k, 1e3))
    fixed, means = choose_fixed(grid, ["a", "b"])
    best = int(np.argmin(a + b))
    assert fixed[peer] == PEER_GRIDS[peer][best]
    assert means[peer][setting_label(PEER_GRIDS[peer][best])] == pytest.approx((a + b)[best] / 2)
    assert set(fixed) == {peer}
    fixed_b, _ = choose_fixed(grid, ["b"])
    assert fixed_b[peer] == PEER_GRIDS[peer][-1]


def test_oracle_is_the_best_grid_point_and_never_worse_than_fixed():
    peer = "pymeshlab-taubin"
    k = len(PEER_GRIDS[peer])
    rng = np.random.default_rng(0)
    base = {"split": "validation", "case": "x", "input_theta": 30.0}
    for lo, hi in ((5.0, 40.0), (31.0, 60.0)):  # second: every run that works is worse than input
        thetas = rng.uniform(lo, hi, k)
        thetas[3] = 30.0  # a failed run is recorded with the input's theta (see _peer_grid)
        grid = _grid("x", peer, thetas, errors=(3,))
        for fixed_params in PEER_GRIDS[peer]:
            rows = {r["method"]: r for r in peer_rows(base, grid, {peer: fixed_params})}
            fx, orc = rows[f"{peer}:fixed"], rows[f"{peer}:oracle"]
            assert orc["theta_deg"] <= fx["theta_deg"]
            assert fx["setting"] == setting_label(fixed_params)
            assert fx["above_input"] == (fx["theta_deg"] > 30.0)
            assert fx["error"] == ("boom" if fixed_params == PEER_GRIDS[peer][3] else "")
        assert orc["theta_deg"] == pytest.approx(thetas.min())
        assert orc["error"] == ("boom" if lo > 30 else "") and not orc["above_input"]


def test_oracle_never_worse_than_fixed_with_the_real_peers():
    require_module("pymeshlab")
    require_module("open3d")
    from spectrageo import metrics, noise
    from spectrageo.datasets import fandisk

    m = fandisk()
    V, F = m.vertices, m.faces
    Vn = noise.generate(V, F, kind="gaussian-normal", level=0.3, rng=0).vertices
    inp = metrics.theta_deg(Vn, V, F)
    base = {"split": "validation", "case": "fandisk", "input_theta": inp}
    for peer in PEER_GRIDS:
        grid = ev._peer_grid("fandisk", "validation", peer, Vn, V, F, inp)
        assert [g["setting"] for g in grid] == [setting_label(p) for p in PEER_GRIDS[peer]]
        assert not any(g["error"] for g in grid)
        thetas = [g["theta_deg"] for g in grid]
        assert np.ptp(thetas) > 0.1  # the grid really changes the result
        for params in PEER_GRIDS[peer]:
            rows = {r["method"]: r for r in peer_rows(base, grid, {peer: params})}
            assert rows[f"{peer}:oracle"]["theta_deg"] <= rows[f"{peer}:fixed"]["theta_deg"]
        assert rows[f"{peer}:oracle"]["theta_deg"] == min(thetas) < inp


def test_end_to_end_on_two_small_validation_cases(shared_data, tmp_path):
    res = evaluate_generality(
        shared_data,
        split="validation",
        levels=[0.3],
        kinds=["gaussian-normal"],
        models=["rotor", "cad/angle_block"],
        out=tmp_path / "gen",
    )
    assert res.fixed_source == "frozen"
    cases = list(dict.fromkeys(r["case"] for r in res.rows))
    assert cases == ["meshes/rotor:gaussian-normal@0.3", "cad/angle_block:gaussian-normal@0.3"]
    peers = [p for p in PEER_GRIDS if ev._peer_available(p)]
    if in_ci():  # .ci/run installs the peers: none may drop out of the protocol there
        assert peers == list(PEER_GRIDS)
    assert len(res.rows) == 2 * (2 + 2 * len(peers))
    assert len(res.grid) == 2 * sum(len(PEER_GRIDS[p]) for p in peers)
    for case in cases:
        rs = {r["method"]: r for r in res.rows if r["case"] == case}
        inp = {r["input_theta"] for r in rs.values()}
        assert len(inp) == 1 and 20 < inp.pop() < 90  # one noisy input per case
        assert rs["tsgsp"]["time_s"] > 0 and rs["gnf"]["time_s"] > 0
        assert np.isfinite(rs["tsgsp"]["theta_deg"]) and not rs["tsgsp"]["error"]
        for p in peers:
            assert rs[f"{p}:oracle"]["theta_deg"] <= rs[f"{p}:fixed"]["theta_deg"]
            assert rs[f"{p}:fixed"]["setting"] == setting_label(PEER_FIXED[p])
    md = (tmp_path / "gen.md").read_text()
    assert md.startswith("## Denoising generality protocol")
    assert "| cases | 2 |" in md and "### Per case" in md
    assert "| validation | meshes/rotor:gaussian-normal@0.3 | 600 |" in md
    assert "cases where tsgsp beats gnf" in md
    with open(tmp_path / "gen.csv") as fh:
        got = list(csv.DictReader(fh))
    assert list(got[0]) == list(PROTOCOL_COLUMNS) and len(got) == len(res.rows)
    assert {r["method"] for r in got} >= {"tsgsp", "gnf"}
    assert float(got[0]["theta_deg"]) == pytest.approx(res.rows[0]["theta_deg"])
    with open(tmp_path / "gen_grid.csv") as fh:
        reader = csv.DictReader(fh)
        grid = list(reader)
    assert list(reader.fieldnames) == list(GRID_COLUMNS) and len(grid) == len(res.grid)
    try:
        import matplotlib  # noqa: F401 - the PNG needs it (bench extra)
    except ImportError:
        pass
    else:
        png = (tmp_path / "gen.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    s = ev.generality_summary(res.rows)["validation"]
    assert s["cases"] == 2
    assert s["mean_theta"]["tsgsp"] == pytest.approx(
        np.mean([r["theta_deg"] for r in res.rows if r["method"] == "tsgsp"])
    )


def test_tuning_choice_and_max_vertices(shared_data):
    res = evaluate_generality(
        shared_data,
        split="both",
        levels=[0.3],
        kinds=["gaussian-normal"],
        models=["spot", "rotor", "cad/angle_block"],
        max_vertices=3000,
        methods=["taubin"],
        peers=True,
    )
    cases = list(dict.fromkeys(r["case"] for r in res.rows))
    # rotor (600) and angle_block (352) are validation, spot (2930) tuning
    assert cases == [
        "meshes/spot:gaussian-normal@0.3",
        "meshes/rotor:gaussian-normal@0.3",
        "cad/angle_block:gaussian-normal@0.3",
    ]
    if not res.grid:
        skip_or_fail("no peer installed (Open3D, PyMeshLab)")
    assert res.fixed_source == "tuning run"
    for peer, params in res.fixed.items():  # chosen on spot only: the best grid point there
        spot = [g for g in res.grid if g["case"] == cases[0] and g["method"] == peer]
        assert setting_label(params) == min(spot, key=lambda g: g["theta_deg"])["setting"]
    small = evaluate_generality(
        shared_data, split="validation", levels=[0.3], kinds=["impulsive"],
        models=["rotor", "cad/angle_block"], max_vertices=500, methods=["taubin"], peers=False,
    )  # fmt: skip
    assert {r["case"] for r in small.rows} == {"cad/angle_block:impulsive@0.3"}


def test_validation_of_arguments(shared_data, tmp_path):
    with pytest.raises(InvalidInputError, match="`split` must be one of"):
        protocol_cases("train")
    with pytest.raises(InvalidInputError, match="`kinds` must be one of"):
        protocol_cases("tuning", kinds=["gaussian"])
    with pytest.raises(InvalidInputError, match="`levels` must be a finite number >= 0"):
        protocol_cases("tuning", levels=[-0.1])
    with pytest.raises(InvalidInputError, match="must be a folder"):
        evaluate_generality(tmp_path / "missing")
    with pytest.raises(InvalidInputError, match="no protocol case matches"):
        evaluate_generality(shared_data, models=["nope"])
    with pytest.raises(InvalidInputError, match="`max_vertices` must be a positive integer"):
        evaluate_generality(shared_data, max_vertices=0)
    with pytest.raises(InvalidInputError, match="unknown denoising method"):
        evaluate_generality(shared_data, methods=["nope"])
    with pytest.raises(InvalidInputError, match="protocol mesh 'meshes/rotor.off' not found"):
        evaluate_generality(tmp_path, split="validation", models=["rotor"], peers=False)
    for bad in (0, 1.5, True):
        with pytest.raises(InvalidInputError, match="`repeat` must be a positive integer"):
            evaluate_generality(shared_data, models=["rotor"], repeat=bad)


def test_repeat_reports_the_best_time_and_the_same_theta(shared_data, tmp_path):
    kw = dict(
        split="validation", levels=[0.3], kinds=["gaussian-normal"], models=["rotor"],
        peers=False,
    )  # fmt: skip
    one = evaluate_generality(shared_data, **kw)
    three = evaluate_generality(shared_data, repeat=3, out=tmp_path / "r", **kw)
    assert three.repeat == 3
    for a, b in zip(one.rows, three.rows, strict=True):
        assert a["theta_deg"] == b["theta_deg"] and b["time_s"] > 0
    assert (
        "in-process times are the best of 3 runs per case and method"
        in (tmp_path / "r.md").read_text()
    )


def test_cli_split_options(capsys, shared_data, tmp_path):
    from spectrageo.cli.main import main

    code = main(
        ["evaluate", "denoise", "--data", str(shared_data), "--split", "validation",
         "--levels", "0.3", "--models", "cad/angle_block", "--methods", "taubin",
         "--max-vertices", "1000", "--out", str(tmp_path / "cli")]
    )  # fmt: skip
    out, _ = capsys.readouterr()
    assert code == 0
    assert "### Summary" in out and "cad/angle_block:anisotropic@0.3" in out
    with open(tmp_path / "cli.csv") as fh:
        got = list(csv.DictReader(fh))
    assert {r["corruption"] for r in got} == {
        "gaussian-normal",
        "gaussian-random",
        "impulsive",
        "region-varying",
        "anisotropic",
    }
    assert {r["level"] for r in got} == {"0.3"}
    for argv, msg in (
        (["--levels", "0.3"], "`--levels` needs `--split"),
        (["--split", "both", "--levels", "a,b"], "`--levels` must be comma-separated numbers"),
        (["--split", "validation", "--repeat", "0"], "--repeat must be a positive integer"),
        (["--repeat", "3"], "`--repeat` needs `--split"),
    ):
        code = main(["evaluate", "denoise", "--data", str(shared_data), *argv])
        _, err = capsys.readouterr()
        assert code != 0 and msg in err
    code = main(["evaluate", "outliers", "--data", str(shared_data), "--split", "both"])
    _, err = capsys.readouterr()
    assert code != 0 and "applies to `evaluate denoise` and `compress` only" in err


def test_time_ratios_where_both_denoised_leave_out_gate_only_cases():
    """A case where the gate returned the input for both methods (theta == input theta) times
    the gate twice, and one where both returned the same repaired mesh (impulse repair) times
    the guard twice; the '... where both filters ran' ratios leave both out and the second
    counts as a tie."""

    def row(case, method, n, theta, t):
        return {
            "split": "validation", "case": case, "method": method, "n_vertices": n,
            "theta_deg": theta, "input_theta": 10.0, "above_input": theta > 10.0,
            "time_s": t, "error": "",
        }  # fmt: skip

    rows = [
        row("a", "tsgsp", 6000, 4.0, 1.0),
        row("a", "gnf", 6000, 5.0, 4.0),
        row("b", "tsgsp", 8000, 10.0, 0.3),  # gate only: both unchanged
        row("b", "gnf", 8000, 10.0, 0.2),
        row("c", "tsgsp", 9000, 6.0, 2.0),
        row("c", "gnf", 9000, 6.5, 5.0),
        row("d", "tsgsp", 7000, 3.0, 0.25),  # impulse repair: the same mesh from both
        row("d", "gnf", 7000, 3.0, 0.2),
    ]
    s = ev.generality_summary(rows)["validation"]
    assert s["tsgsp_ties_gnf"] == 2 and s["tsgsp_beats_gnf_pct"] == pytest.approx(50.0)
    assert s["time_ratio_max_5k"] == pytest.approx(1.5)  # the gate-only case
    assert s["time_ratio_max_5k_denoised"] == pytest.approx(0.4)
    assert s["time_ratio_median_denoised"] == pytest.approx(0.325)
    assert s["cli_time_ratio_median"] is None  # no CLI timings in these rows
    for r, cli in zip(rows, (2.0, 4.0, 1.0, 0.9, 3.0, 5.0, 1.0, 0.9), strict=True):
        r["cli_time_s"] = cli
    s = ev.generality_summary(rows)["validation"]
    assert s["cli_time_ratio_max_5k_denoised"] == pytest.approx(0.6)
    assert s["cli_time_ratio_median_denoised"] == pytest.approx(0.55)
    assert s["cli_time_ratio_median"] == pytest.approx(np.median([0.5, 1.0 / 0.9, 0.6, 1.0 / 0.9]))
