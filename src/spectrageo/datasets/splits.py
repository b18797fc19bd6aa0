"""One registry of the evaluation data and of the tuned defaults (which data chose what).

Every evaluation of the package (``spectrageo evaluate ...``, :mod:`spectrageo.learn.evaluate`,
the ``benchmarks/`` scripts) reads its cases from :data:`CASES`, and every default that was chosen
by measuring something is listed in :data:`DEFAULTS` with the data it was chosen on. The tests
(``tests/test_splits.py``) check that the values here are the values in the code, that no file
is in two splits of one task, and that every file exists in the shared data.

Splits (:data:`SPLITS`):

* ``tuning``: data a default may be chosen on;
* ``validation``: data meant to inform no choice, used for reporting. Where a validation case was
  looked at when a rule or a constant was designed anyway, :attr:`Case.consulted_by` names those
  defaults: the case is no longer held out for them (:meth:`Case.held_out_for`);
* ``test``: sealed data, reported once (none registered yet: the registry supports it).

The split of a default (:attr:`Default.split`) is ``tuning`` when only tuning data chose its
value, ``tuning+validation`` when validation data of its task did as well, and ``evaluation``
when it was chosen on the data that is also its whole evaluation (no held-out data at all).

Groups (:data:`GROUPS`) say what kind of shape a case holds: ``organic`` (scanned or sculpted
smooth shapes), ``cad`` (tessellated mechanical parts), ``lowpoly`` (under 1,000 vertices),
``large`` (over 50,000 vertices), ``scan`` (raw point scans and range maps), ``animation`` (mesh
animations and point sequences), ``synthetic`` (scenes generated from the shared models).

The registry is data only (this module, the lookups, and one data module ``_split_<area>.py`` per
area): it imports nothing from the application packages.
"""

from __future__ import annotations

from ._split_complete import HOLE_TUNING, HOLE_VALIDATION, _completion_cases
from ._split_compress import COMPRESS_LARGE, _compress_cases, _connectivity_cases
from ._split_defaults import DEFAULTS
from ._split_denoise import (
    DENOISE_LEFT_OUT,
    DENOISE_PAIRS,
    DENOISE_SAME_SHAPE_AS_TUNING,
    DENOISE_VALIDATION_CONSULTED,
    DENOISE_VALIDATION_RULES,
    GATE_SPLIT_LIMIT,
    _denoise_cases,
    _denoise_dynamic_cases,
    _denoise_frame_cases,
    _denoise_generality_cases,
    _gate_cases,
)
from ._split_learn import (
    LEARN_REPORT_MESH,
    LEARN_TRAIN_MESHES,
    SALIENCY_CONSULTED,
    _learn_cases,
    _saliency_cases,
)
from ._split_outliers import OUTLIER_PATTERNS_BY_SPLIT, OUTLIER_SCANS_CONSULTED, _outlier_cases
from ._split_register import IDENTIFY_LIBRARY, _register_cases
from ._split_sealed import _test_cases
from ._split_types import DEFAULT_SPLITS, GROUPS, SPLITS, Case, Default

#: every evaluation case, in the order the evaluations run them
CASES: tuple[Case, ...] = tuple(
    _denoise_cases()
    + _gate_cases()
    + _denoise_frame_cases()
    + _denoise_dynamic_cases()
    + _denoise_generality_cases()
    + _outlier_cases()
    + _compress_cases()
    + _connectivity_cases()
    + _completion_cases()
    + _register_cases()
    + _saliency_cases()
    + _learn_cases()
    + _test_cases()
)


# ================================================================================= lookups
def tasks() -> tuple[str, ...]:
    """The tasks of :data:`CASES`, in registry order."""
    return tuple(dict.fromkeys(c.task for c in CASES))


def _check(value, name: str, allowed) -> None:
    if value not in allowed:
        raise ValueError(f"`{name}` must be one of {tuple(allowed)}; got {value!r}.")


def cases(task: str, split: str | None = None, *, group: str | None = None) -> tuple[Case, ...]:
    """The cases of ``task`` (of one ``split`` / ``group`` when given), in registry order."""
    _check(task, "task", tasks())
    if split is not None:
        _check(split, "split", SPLITS)
    if group is not None:
        _check(group, "group", GROUPS)
    return tuple(
        c for c in CASES if c.task == task and split in (None, c.split) and group in (None, c.group)
    )


def files(task: str, split: str | None = None) -> tuple[str, ...]:
    """The files of the cases of ``task`` (and ``split``), in order, each once."""
    return tuple(dict.fromkeys(c.file for c in cases(task, split) if c.file))


def split_of(task: str, key: str, *, seed: int | None = None) -> str | None:
    """The split of the case of ``task`` whose file or name is ``key`` (the first such case,
    or the one with ``seed``); None when the registry has no such case."""
    for c in cases(task):
        if key in (c.file, c.name) and seed in (None, c.seed):
            return c.split
    return None


def consulted(task: str, split: str = "validation") -> tuple[str, ...]:
    """Every default that looked at some case of ``task``/``split`` (not held out for them)."""
    return tuple(dict.fromkeys(d for c in cases(task, split) for d in c.consulted_by))


def defaults(split: str | None = None, *, task: str | None = None) -> tuple[Default, ...]:
    """The registered defaults (chosen on ``split`` / for ``task`` when given)."""
    if split is not None:
        _check(split, "split", DEFAULT_SPLITS)
    return tuple(d for d in DEFAULTS if split in (None, d.split) and task in (None, d.task))


def default(name: str) -> Default:
    """The registry entry of one default, by qualified name."""
    for d in DEFAULTS:
        if d.name == name:
            return d
    raise KeyError(f"no registered default {name!r}.")


__all__ = [
    "CASES",
    "COMPRESS_LARGE",
    "DEFAULTS",
    "DEFAULT_SPLITS",
    "DENOISE_LEFT_OUT",
    "DENOISE_PAIRS",
    "DENOISE_SAME_SHAPE_AS_TUNING",
    "DENOISE_VALIDATION_CONSULTED",
    "DENOISE_VALIDATION_RULES",
    "GATE_SPLIT_LIMIT",
    "GROUPS",
    "HOLE_TUNING",
    "HOLE_VALIDATION",
    "IDENTIFY_LIBRARY",
    "LEARN_REPORT_MESH",
    "LEARN_TRAIN_MESHES",
    "OUTLIER_PATTERNS_BY_SPLIT",
    "OUTLIER_SCANS_CONSULTED",
    "SALIENCY_CONSULTED",
    "SPLITS",
    "Case",
    "Default",
    "cases",
    "consulted",
    "default",
    "defaults",
    "files",
    "split_of",
    "tasks",
]
