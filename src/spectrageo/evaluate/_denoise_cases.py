"""Cases of the denoising evaluation: the protocol's splits, the peers' settings, result records."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from .._errors import InvalidInputError
from .._validation import check_choice
from ..datasets.splits import DENOISE_LEFT_OUT, DENOISE_SAME_SHAPE_AS_TUNING
from ..datasets.splits import cases as _cases
from ..datasets.splits import files as _files
from ..noise._core import check_level

#: columns of the table, in order
COLUMNS = (
    "pair",
    "method",
    "n_vertices",
    "theta_deg",
    "dmean",
    "dmax",
    "dist_n",
    "nmsve",
    "dmean_n",
    "hd_mean",
    "time_s",
    "split",
)

#: peer methods run when their package can be imported
PEERS = ("pymeshlab-twostep", "pymeshlab-taubin", "open3d-taubin")

# --------------------------------------------------------------------------- generality protocol
# `spectrageo evaluate denoise --split tuning|validation|both` (issue 14). Two disjoint splits of
# the shared data are fixed here; every default of the package's denoisers and the peers' fixed
# settings may be chosen on TUNING only, and VALIDATION is used for nothing but reporting.

#: Tuning split, part 1: the shared noisy / ground-truth pairs of ``denoise/``. TSGSP's and GNF's
#: defaults (reading choices, the do-no-harm gate ``min_noise``) were chosen on them. Read from the
#: split registry (:mod:`spectrageo.datasets.splits`, task ``denoise``), as are the lists below.
TUNING_PAIRS = tuple(c.name for c in _cases("denoise", "tuning") if c.corruption == "pair")
#: Tuning split, part 2: clean meshes corrupted by :func:`spectrageo.noise.generate`. These four
#: (at Gaussian noise 0.3) informed TSGSP's ``area_weights`` and ``input_weight=0.7`` (see the
#: generality section of BENCHMARKS.md), so they may never be used for validation.
TUNING_MESHES = tuple(c.file for c in _cases("denoise", "tuning") if c.corruption == "generated")
#: Shapes kept out of both splits' generated cases because another tessellation of the same object
#: is a tuning pair (fandisk, the Stanford bunny, the block): validating on them would not be
#: held out.
SAME_SHAPE_AS_TUNING = DENOISE_SAME_SHAPE_AS_TUNING
#: Validation split: clean meshes of ``meshes/`` and ``cad/`` meant to play no part in choosing
#: defaults, corrupted by :func:`spectrageo.noise.generate` (every kind at every level). The
#: rules designed or revisited after this split had been looked at are the ``consulted_by`` of
#: its registry cases (:data:`spectrageo.datasets.splits.DENOISE_VALIDATION_CONSULTED`, disclosed
#: in the report header): the split is not held out for them. It holds organic
#: scans, CAD tessellations with long thin triangles and mixed element sizes (the whole ``cad/``
#: folder: trimesh's parts, cycloidal, partLp, joint, screwdriver, ABC 00000050) and a mesh of more
#: than 100k vertices (the dragon at 100,250 vertices). In neither split: :data:`LEFT_OUT`.
VALIDATION_MESHES = _files("denoise", "validation")
#: Shared clean meshes in neither split: the 6-vertex octahedron (too small for a noise estimate)
#: and the two other resolutions of the validation dragon (the same object; the 437k-vertex one
#: would also make a full run take most of a day on 2 cores).
LEFT_OUT = DENOISE_LEFT_OUT
SPLIT_CHOICES = ("tuning", "validation", "both")
#: methods of this package run by the protocol (default settings)
PROTOCOL_METHODS = ("tsgsp", "gnf")

_TAUBIN_PAIRS = ((0.5, -0.53), (0.33, -0.34))
#: Parameter grid of every peer (keyword arguments of the underlying filter): the per-case oracle
#: is the best of the grid, the fixed setting the grid point with the lowest mean theta on the
#: tuning split. Each grid holds the library's default. The two-step grid pairs the normal
#: smoothing and vertex fitting iterations: MeshLab's default of 20 fitting steps undoes much of
#: the smoothing, and 2 fitting steps did best on the tuning split.
PEER_GRIDS: dict[str, tuple[dict, ...]] = {
    "pymeshlab-twostep": tuple(
        {"stepsmoothnum": it, "normalthr": thr, "stepnormalnum": ns, "stepfitnum": fit}
        for it in (1, 3, 6)
        for thr in (60.0, 90.0)
        for ns, fit in ((2, 2), (5, 2), (20, 20))
    ),
    "pymeshlab-taubin": tuple(
        {"stepsmoothnum": it, "lambda_": lam, "mu": mu}
        for it in (2, 5, 10, 20, 50, 100)
        for lam, mu in _TAUBIN_PAIRS
    ),
    "open3d-taubin": tuple(
        {"number_of_iterations": it, "lambda_filter": lam, "mu": mu}
        for it in (2, 5, 10, 20, 50, 100)
        for lam, mu in _TAUBIN_PAIRS
    ),
}
#: The peers' fixed settings: the lowest mean theta over the tuning cases (chosen on the tuning
#: split; see docs/decisions.md#denoise-peer-fixed). ``--split validation`` uses these;
#: ``--split tuning``/``both`` re-choose them on that run's tuning cases and say whether they differ.
PEER_FIXED: dict[str, dict] = {
    "pymeshlab-twostep": {
        "stepsmoothnum": 6,
        "normalthr": 90.0,
        "stepnormalnum": 2,
        "stepfitnum": 2,
    },
    "pymeshlab-taubin": {"stepsmoothnum": 50, "lambda_": 0.33, "mu": -0.34},
    "open3d-taubin": {"number_of_iterations": 50, "lambda_filter": 0.33, "mu": -0.34},
}

#: columns of the protocol's per-case CSV (one row per case and method; peers appear as
#: ``<peer>:fixed`` and ``<peer>:oracle``)
PROTOCOL_COLUMNS = (
    "split",
    "case",
    "model",
    "corruption",
    "level",
    "n_vertices",
    "method",
    "setting",
    "theta_deg",
    "input_theta",
    "above_input",
    "time_s",
    "cli_time_s",
    "error",
)
#: columns of the ``<out>_grid.csv`` file: every peer grid point on every case
GRID_COLUMNS = ("split", "case", "method", "setting", "theta_deg", "time_s", "error")

_SHORT = {
    "stepsmoothnum": "iter",
    "number_of_iterations": "iter",
    "normalthr": "thr",
    "stepnormalnum": "nsteps",
    "stepfitnum": "fit",
    "lambda_": "lambda",
    "lambda_filter": "lambda",
}


def setting_label(params: dict) -> str:
    """Short text of a peer setting, e.g. ``"iter=3 thr=60 nsteps=20"``."""
    return " ".join(f"{_SHORT.get(k, k)}={v:g}" for k, v in params.items())


@dataclass(frozen=True)
class ProtocolCase:
    """One case of the generality protocol: a shared pair or a clean mesh + a corruption."""

    split: str
    model: str  # pair name, or the mesh path relative to the data folder
    corruption: str  # "pair" or one of spectrageo.noise.GENERATOR_KINDS
    level: float  # nan for pairs
    seed: int  # 0 for pairs

    @property
    def label(self) -> str:
        """The model without folder suffixes: ``Block0.4``, ``cad/joint``, ``meshes/joint``."""
        if self.corruption == "pair":
            return self.model
        name = self.model
        for suf in (".gz", ".ply", ".off", ".obj", ".stl", ".STL"):
            name = name.removesuffix(suf)
        return name

    @property
    def name(self) -> str:
        if self.corruption == "pair":
            return self.model
        return f"{self.label}:{self.corruption}@{self.level:g}"


def protocol_cases(
    split: str = "both", *, levels=None, kinds=None, seed: int = 0
) -> list[ProtocolCase]:
    """The cases of one split (or both, tuning first), in run order.

    Tuning: the :data:`TUNING_PAIRS` as given, then every :data:`TUNING_MESHES` mesh with every
    corruption ``kinds`` at every ``levels``; validation: the same for :data:`VALIDATION_MESHES`.
    Each generated case has its own seed, a function of (model, kind, level, ``seed``) only, so a
    case is the same whatever else is run.
    """
    from ..noise.generator import GENERATOR_KINDS, GENERATOR_LEVELS, case_seed

    check_choice(split, "split", SPLIT_CHOICES)
    levels = GENERATOR_LEVELS if levels is None else tuple(float(x) for x in levels)
    for x in levels:
        check_level(x, "levels")
    kinds = GENERATOR_KINDS if kinds is None else tuple(kinds)
    for k in kinds:
        check_choice(k, "kinds", GENERATOR_KINDS)
    out: list[ProtocolCase] = []
    for sp in ("tuning", "validation"):
        if split not in (sp, "both"):
            continue
        if sp == "tuning":
            out += [ProtocolCase(sp, p, "pair", float("nan"), 0) for p in TUNING_PAIRS]
        meshes = TUNING_MESHES if sp == "tuning" else VALIDATION_MESHES
        for rel in meshes:
            for k in kinds:
                for lv in levels:
                    out.append(ProtocolCase(sp, rel, k, lv, case_seed(rel, k, lv, seed=seed)))
    return out


def _load_clean(data_dir: Path, case: ProtocolCase):
    """(V_input_or_None, V_clean, F) of a case's model (pairs give their noisy input)."""
    from .. import io
    from ..datasets import denoise_pairs

    if case.corruption == "pair":
        found = {p[0]: p for p in denoise_pairs(data_dir)}
        if case.model not in found:
            raise InvalidInputError(f"tuning pair {case.model!r} not found under {data_dir}.")
        _, noisy_path, orig_path = found[case.model]
        noisy, orig = io.read_mesh(noisy_path), io.read_mesh(orig_path)
        if noisy.vertices.shape != orig.vertices.shape:
            raise InvalidInputError(f"pair {case.model}: noisy and original vertex counts differ.")
        return noisy.vertices, orig.vertices, orig.faces
    path = data_dir / case.model
    if not path.is_file():
        raise InvalidInputError(f"protocol mesh {case.model!r} not found under {data_dir}.")
    m = io.read_mesh(path)
    return None, m.vertices, m.faces


@dataclass
class GeneralityResult:
    """What :func:`evaluate_generality` measured.

    Attributes
    ----------
    rows : list of dict
        One per case and method (keys :data:`PROTOCOL_COLUMNS`); peers as ``<peer>:fixed`` (the
        fixed setting) and ``<peer>:oracle`` (the best grid point on that case).
    grid : list of dict
        Every peer grid point on every case (keys :data:`GRID_COLUMNS`).
    fixed : dict
        The fixed setting used per peer (keyword arguments).
    fixed_source : str
        ``"tuning run"`` (chosen on this run's tuning cases) or ``"frozen"`` (:data:`PEER_FIXED`).
    tuning_means : dict
        ``peer -> {setting label: mean theta over this run's tuning cases}`` (empty without them).
    repeat : int
        Runs per timing (the best is reported).
    """

    rows: list[dict]
    grid: list[dict]
    fixed: dict
    fixed_source: str
    tuning_means: dict = field(default_factory=dict)
    repeat: int = 1
