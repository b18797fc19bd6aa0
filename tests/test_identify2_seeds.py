"""The identification scenes of the split registry and the evaluation's choice of scenes
(docs/decisions.md#identify2-tuning-split)."""

from __future__ import annotations

import pytest

from spectrageo._errors import InvalidInputError


def test_parse_seeds_and_the_registered_tuning_scenes():
    from spectrageo.datasets.splits import cases
    from spectrageo.evaluate.identify import TUNING, VALIDATION, parse_seeds

    assert parse_seeds("1-3,11, 31-33") == (1, 2, 3, 11, 31, 32, 33)
    with pytest.raises(InvalidInputError):
        parse_seeds("1-x")
    assert TUNING["seeds"] == (*range(1, 11), *range(31, 51))
    assert VALIDATION["seeds"] == tuple(range(11, 19))
    # no scene seed in two splits, none of the speed benchmark's (21-23)
    seeds = [c.seed for c in cases("identify") if c.file is None]
    assert len(seeds) == len(set(seeds)) and not set(seeds) & {21, 22, 23}


def test_evaluate_rejects_unregistered_seeds(tmp_path):
    from spectrageo.evaluate.identify import evaluate

    with pytest.raises(InvalidInputError, match="not in the split registry"):
        evaluate(tmp_path, seeds="19-20", parts=())


def test_default_and_chosen_scenes(tmp_path, monkeypatch):
    import spectrageo.evaluate.identify as ev

    seen = []
    monkeypatch.setattr(ev, "load_library", lambda data: {"m": None})
    monkeypatch.setattr(ev, "_scenes", lambda lib, split, s, p: seen.append((split, s)) or [])
    monkeypatch.delenv("SPECTRAGEO_IDENTIFY_SEEDS", raising=False)
    ev.evaluate(tmp_path, parts=("scene",))
    assert seen == [("tuning", (1, 2, 3)), ("validation", tuple(range(11, 19)))]
    seen.clear()
    monkeypatch.setenv("SPECTRAGEO_IDENTIFY_SEEDS", "31-33,12")
    ev.evaluate(tmp_path, parts=("scene",))
    assert seen == [("tuning", (31, 32, 33)), ("validation", (12,))]
    seen.clear()
    ev.evaluate(tmp_path, parts=("scene",), seeds="all")
    assert seen == [("tuning", ev.TUNING["seeds"]), ("validation", ev.VALIDATION["seeds"])]


def test_pose_errors_of_a_present_model():
    from types import SimpleNamespace

    import numpy as np

    from spectrageo.evaluate.identify import pose_errors

    Tg = np.eye(4)
    Tg[:3, 3] = [1.0, 0.0, 0.0]
    sc = SimpleNamespace(names=("a", "b"), poses=np.stack([np.eye(4), Tg]), occlusion=[0.2, 0.7])
    T = Tg.copy()
    T[:3, 3] += [0.01, 0.0, 0.0]
    m = SimpleNamespace(model="b", transformation=T, found=True)
    e = pose_errors(m, sc)
    assert e["occlusion"] == 0.7 and e["recognized"]
    assert e["rot_err_deg"] == 0.0 and abs(e["trans_err"] - 0.01) < 1e-12
    m = SimpleNamespace(model="b", transformation=np.eye(4), found=True)
    assert not pose_errors(m, sc)["recognized"]  # 1 diagonal off
