"""Types of the split registry: cases, tuned defaults, splits and shape groups."""

from __future__ import annotations

from dataclasses import dataclass

#: the splits a case can be in
SPLITS = ("tuning", "validation", "test")
#: the data a default can have been chosen on
DEFAULT_SPLITS = ("tuning", "tuning+validation", "evaluation")
#: shape groups of the cases
GROUPS = ("organic", "cad", "lowpoly", "large", "scan", "animation", "synthetic")


@dataclass(frozen=True)
class Case:
    """One evaluation case.

    Attributes
    ----------
    task : str
        The evaluation it belongs to (``denoise``, ``outliers``, ``compress``, ...; :func:`tasks`).
    file : str or None
        Path relative to the shared data folder of the data the case reads (for a noisy /
        ground-truth pair: the noisy file); None for generated cases (see ``sources``).
    split : {"tuning", "validation", "test"}
    group : str
        Shape group (:data:`GROUPS`).
    corruption : str
        What is done to the data (``"pair"``: the given noisy file; ``"generated"``: the kinds x
        levels of :func:`spectrageo.noise.generate`; ``"clean"``; ``"motion"``; a pattern list).
    seed : int
        Seed of the corruption (the evaluation may derive per-run seeds from it).
    name : str
        The label the evaluation prints (defaults to ``file``).
    sources : tuple of str
        Other files the case reads (a ground truth, a pair's second scan, a scene's models).
    consulted_by : tuple of str
        Defaults (qualified names as in :data:`DEFAULTS`, or a named rule) whose design or value
        looked at this case although it is not tuning data; the case is not held out for them.
    note : str
    root : {"shared", "test", "repo"}
        The folder ``file`` is relative to: the shared data folder, the sealed test data
        folder (``$SPECTRAGEO_TEST_DATA``, fetched by ``benchmarks/test_split/fetch.py``), or the
        repository's ``benchmarks/data`` (small files shipped with the source).
    """

    task: str
    file: str | None
    split: str
    group: str
    corruption: str = "clean"
    seed: int = 0
    name: str = ""
    sources: tuple[str, ...] = ()
    consulted_by: tuple[str, ...] = ()
    note: str = ""
    root: str = "shared"

    def __post_init__(self) -> None:
        if self.root not in ("shared", "test", "repo"):
            raise ValueError(f"`root` must be 'shared', 'test' or 'repo'; got {self.root!r}.")
        if self.split not in SPLITS:
            raise ValueError(f"`split` must be one of {SPLITS}; got {self.split!r}.")
        if self.group not in GROUPS:
            raise ValueError(f"`group` must be one of {GROUPS}; got {self.group!r}.")
        if not self.name:
            object.__setattr__(self, "name", self.file or "")

    @property
    def held_out(self) -> bool:
        """Not tuning data, and consulted by no default."""
        return self.split != "tuning" and not self.consulted_by

    def held_out_for(self, default: str) -> bool:
        """Whether this case is held-out data for ``default`` (a qualified name)."""
        return self.split != "tuning" and default not in self.consulted_by

    @property
    def files(self) -> tuple[str, ...]:
        """Every file the case reads (``file`` first, then ``sources``)."""
        return ((self.file,) if self.file else ()) + self.sources


@dataclass(frozen=True)
class Default:
    """One tuned default.

    Attributes
    ----------
    name : str
        Qualified name: ``module.CONSTANT``, ``module.function.parameter`` or a key of a constant
        dict as ``module.CONSTANT[key]`` (``tests/test_splits.py`` reads the value in the code).
    value : object
        The value in the code.
    split : {"tuning", "tuning+validation", "evaluation"}
        The data it was chosen on, among the cases of ``task``.
    task : str
        The task whose splits ``split`` refers to.
    chosen_by : str
        The benchmark script or command whose runs chose it.
    note : str
        One line: what was measured, or where the choice is documented.
    """

    name: str
    value: object
    split: str
    task: str
    chosen_by: str
    note: str = ""

    def __post_init__(self) -> None:
        if self.split not in DEFAULT_SPLITS:
            raise ValueError(f"`split` must be one of {DEFAULT_SPLITS}; got {self.split!r}.")


def _c(task, file, split, group, corruption="clean", seed=0, name="", sources=(), **kw) -> Case:
    return Case(task, file, split, group, corruption, seed, name, tuple(sources), **kw)


# =============================================================================== shape groups
#: the group of every shared mesh used by a case (anything not listed: ``organic``)
_GROUP = {
    "meshes/ChineseDragon-10kv.off": "organic",
    "meshes/anchor_dense.off": "cad",
    "meshes/blade.off": "cad",
    "meshes/cheese.off": "cad",
    "meshes/cube-meshed.off": "lowpoly",
    "meshes/dragon_vrip.ply.gz": "large",
    "meshes/dragon_vrip_res2.ply.gz": "large",
    "meshes/fandisk.off": "cad",
    "meshes/fandisk_large.off": "cad",
    "meshes/joint.off": "lowpoly",
    "meshes/octahedron.off": "lowpoly",
    "meshes/rotor.off": "lowpoly",
    "meshes/turbine.off": "cad",
    "cad/angle_block.STL": "lowpoly",
    "cad/plate_holes.STL": "lowpoly",
    "saliency/block.obj": "cad",
    "saliency/cad.obj": "cad",
    "saliency/casting.obj": "cad",
    "saliency/fandisk.obj": "cad",
    "holes/mech-holes-shark.off": "cad",
    "scans/rangemap/face000.ply": "scan",
}


def _group(rel: str) -> str:
    if rel in _GROUP:
        return _GROUP[rel]
    if rel.startswith("cad/"):
        return "cad"
    if rel.startswith("animations/") or rel.startswith("scans/pcl/grabber"):
        return "animation"
    if rel.startswith("scans/"):
        return "scan"
    return "organic"


def _d(name, value, split, task, chosen_by, note="") -> Default:
    return Default(name, value, split, task, chosen_by, note)
