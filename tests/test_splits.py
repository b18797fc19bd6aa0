"""The split registry (:mod:`spectrageo.datasets.splits`): its defaults are the code's, every
default is chosen on tuning data (known exceptions marked), splits are disjoint by file, and every
case's file is in the shared data."""

from __future__ import annotations

import importlib
import inspect
from collections import defaultdict

import pytest

from spectrageo.datasets import splits as S

#: Defaults recorded as chosen on data other than the tuning split. Each one is an expected
#: failure of ``test_default_chosen_on_tuning_data`` (strict: once it is re-chosen on tuning data
#: and recorded as ``tuning`` in the registry, the test passes unexpectedly and fails the run, and
#: its name must be removed here).
NOT_TUNING_YET: dict[str, str] = {}

#: Tasks whose validation split reuses files of its tuning split (other seeds or motions).
SHARED_FILES = {
    "register": "the bunny and fragment scan pairs are in both splits, with other motions",
    "completion": "fandisk is the tuning mesh (seed 1) and a validation mesh (seed 0)",
    "completion-animation": "horse-gallop and cat-poses are tuned with seed 1, evaluated seed 0",
}


def _resolve(name: str):
    """The value in the code of a qualified default name (see :class:`splits.Default`)."""
    base, *keys = name.split("[")
    parts = base.split(".")
    for i in range(len(parts), 0, -1):
        mod_name = ".".join(parts[:i])
        try:
            obj = importlib.import_module(mod_name)
        except ModuleNotFoundError as exc:
            if exc.name is not None and not mod_name.startswith(exc.name):
                raise
            continue
        rest = parts[i:]
        break
    else:  # pragma: no cover - every name starts with "spectrageo"
        raise AssertionError(f"no module in {name!r}")
    for j, attr in enumerate(rest):
        if hasattr(obj, attr) and not (
            j == len(rest) - 1 and callable(obj) and _is_param(obj, attr)
        ):
            obj = getattr(obj, attr)
        elif j == len(rest) - 1 and callable(obj):
            par = inspect.signature(obj).parameters[attr]
            assert par.default is not inspect.Parameter.empty, f"{name} has no default"
            obj = par.default
        else:
            raise AssertionError(f"{name}: {attr!r} not found on {obj!r}")
    for k in keys:
        obj = obj[k.rstrip("]")]
    return obj


def _is_param(fn, attr: str) -> bool:
    try:
        return attr in inspect.signature(fn).parameters
    except (TypeError, ValueError):
        return False


@pytest.mark.parametrize("d", S.DEFAULTS, ids=[d.name for d in S.DEFAULTS])
def test_registry_value_is_the_code_default(d):
    got = _resolve(d.name)
    assert type(got) is type(d.value) and got == d.value, (
        f"{d.name}: registry {d.value!r}, code {got!r}; update the registry (and its split) "
        "together with the default"
    )


def _tuning_params():
    out = []
    for d in S.DEFAULTS:
        marks = ()
        if d.name in NOT_TUNING_YET:
            reason = (
                f"{d.name} was chosen on {d.split} data ({NOT_TUNING_YET[d.name]}); re-choose "
                "it on the tuning split, record split='tuning' and remove it from NOT_TUNING_YET"
            )
            marks = (pytest.mark.xfail(strict=True, reason=reason),)
        out.append(pytest.param(d, id=d.name, marks=marks))
    return out


@pytest.mark.parametrize("d", _tuning_params())
def test_default_chosen_on_tuning_data(d):
    assert d.split == "tuning", f"{d.name}: chosen on {d.split} data ({d.note})"


def test_known_exceptions_are_registered():
    names = {d.name for d in S.DEFAULTS}
    assert set(NOT_TUNING_YET) <= names
    assert len(names) == len(S.DEFAULTS), "a default is registered twice"


def _split_files(task: str) -> dict[str, set[str]]:
    by: dict[str, set[str]] = defaultdict(set)
    for c in S.cases(task):
        if c.file:
            by[c.split].add(c.file)
    return by


def _task_params():
    out = []
    for t in S.tasks():
        marks = ()
        if t in SHARED_FILES:
            marks = (pytest.mark.xfail(strict=True, reason=SHARED_FILES[t]),)
        out.append(pytest.param(t, id=t, marks=marks))
    return out


@pytest.mark.parametrize("task", _task_params())
def test_no_file_in_two_splits_of_a_task(task):
    by = _split_files(task)
    splits = sorted(by)
    for i, a in enumerate(splits):
        for b in splits[i + 1 :]:
            assert not by[a] & by[b], f"{task}: {sorted(by[a] & by[b])} in {a} and {b}"


def test_shared_files_are_not_held_out():
    """Where a validation case reuses a tuning file, it says whom it is not held out for."""
    for task in SHARED_FILES:
        by = _split_files(task)
        for c in S.cases(task, "validation"):
            if c.file in by["tuning"]:
                assert c.consulted_by and not c.held_out, c


def test_every_case_file_exists(shared_data):  # shared_data fails under CI=true when absent
    shared = [c for c in S.CASES if c.root == "shared"]
    missing = sorted({f for c in shared for f in c.files if not (shared_data / f).exists()})
    assert not missing, f"registry files missing under {shared_data}: {missing}"


def test_consulted_defaults_are_registered():
    names = {d.name for d in S.DEFAULTS}
    for c in S.CASES:
        for d in c.consulted_by:
            assert d in names or d.startswith("rule: "), (c.task, c.file, d)
        if c.split == "tuning":
            assert not c.consulted_by, c
    for rule, ds in S.DENOISE_VALIDATION_RULES.items():
        assert set(ds) <= set(S.DENOISE_VALIDATION_CONSULTED), rule


def test_denoise_validation_is_not_held_out_for_the_consulted_rules():
    val = S.cases("denoise", "validation")
    assert len(val) == 29 and all(not c.held_out for c in val)
    assert set(S.consulted("denoise")) == set(S.DENOISE_VALIDATION_CONSULTED)
    for c in val:
        assert not c.held_out_for("spectrageo.denoise._guard.FOLD_SHARE")
        assert c.held_out_for("spectrageo.denoise._guard.MIN_NOISE")
    assert all(c.held_out_for("anything") is False for c in S.cases("denoise", "tuning"))


def test_cases_are_unique_and_valid():
    keys = [(c.task, c.file, c.name, c.seed, c.corruption) for c in S.CASES]
    assert len(keys) == len(set(keys))
    assert {c.root for c in S.cases("denoise", "test")} == {"test"}
    assert all(c.root in ("shared", "repo") for c in S.CASES if c.split != "test")


def test_lookups():
    assert S.files("compress", "tuning")[:2] == ("meshes/fandisk.off", "cad/partLp.obj")
    assert S.split_of("outliers", "b9") == "validation"
    assert S.split_of("register", "bunny", seed=1) == "tuning"
    assert S.split_of("register", "nothing") is None
    assert S.default("spectrageo.denoise._guard.MIN_NOISE").value == 0.015
    assert S.defaults("evaluation") == ()
    with pytest.raises(KeyError, match="no registered default"):
        S.default("nope")
    with pytest.raises(ValueError, match="`task` must be one of"):
        S.cases("nope")
    with pytest.raises(ValueError, match="`split` must be one of"):
        S.cases("denoise", "training")
    with pytest.raises(ValueError, match="`group` must be one of"):
        S.cases("denoise", group="blob")
    with pytest.raises(ValueError, match="`split` must be one of"):
        S.defaults("validation")
    with pytest.raises(ValueError, match="`split` must be one of"):
        S.Case("x", "f", "train", "cad")
    with pytest.raises(ValueError, match="`group` must be one of"):
        S.Case("x", "f", "tuning", "blob")
    with pytest.raises(ValueError, match="`split` must be one of"):
        S.Default("x", 1, "validation", "t", "b")


def test_registry_imports_no_application_package():
    import ast
    from pathlib import Path

    here = Path(S.__file__)  # splits.py and its data modules _split_*.py
    for path in (here, *sorted(here.parent.glob("_split_*.py"))):
        tree = ast.parse(path.read_text())
        imported = [n for n in ast.walk(tree) if isinstance(n, ast.Import | ast.ImportFrom)]
        assert all(
            isinstance(n, ast.ImportFrom)
            and (
                n.module in ("__future__", "dataclasses")
                or (n.level == 1 and n.module.startswith("_split_"))
            )
            for n in imported
        ), path.name


def test_sealed_test_split_matches_its_manifest():
    """The registry's test cases are the files of ``benchmarks/test_split/manifest.csv`` (the
    download list with sources and checksums), and no test file is read by another split."""
    import csv
    from pathlib import Path

    manifest = Path(__file__).resolve().parents[1] / "benchmarks" / "test_split" / "manifest.csv"
    with open(manifest, newline="") as f:
        rows = list(csv.DictReader(f))
    want = {(r["task"], r["name"], r["file"], r["group"]) for r in rows}
    got = {(c.task, c.name, c.file, c.group) for c in S.CASES if c.split == "test"}
    assert got == want
    assert {r["split"] for r in rows} == {"test"}
    test_names = {c.name.lower() for c in S.CASES if c.split == "test"}
    other = {Path(f).stem.lower() for c in S.CASES if c.split != "test" for f in c.files}
    assert not test_names & other
