"""Options of the training functions, validated on construction."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .._errors import InvalidInputError
from .._validation import check_choice, check_positive
from ..datasets.splits import DENOISE_SAME_SHAPE_AS_TUNING, LEARN_TRAIN_MESHES
from ..datasets.splits import files as _files
from ._features import IMAGE_COLS

#: training meshes of the shipped weights (relative to the shared data folder; the split
#: registry's ``learn-train`` tuning cases, :mod:`spectrageo.datasets.splits`)
TRAIN_MESHES = LEARN_TRAIN_MESHES
#: relative Gaussian noise levels of the training cases
TRAIN_LEVELS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)
#: motion compensation of the temporal rows and targets (:func:`~spectrageo.learn.dae.train_frames_model`)
MOTIONS = ("auto", "rigid", "none")


def check_training_meshes(meshes) -> tuple[str, ...]:
    """Refuse meshes of the validation split, the benchmark pairs or their shapes."""
    banned = set(_files("denoise", "validation")) | set(DENOISE_SAME_SHAPE_AS_TUNING)
    out = []
    for m in meshes:
        m = str(m).replace("\\", "/")
        if m in banned or m.startswith("denoise/"):
            raise InvalidInputError(
                f"training mesh {m!r} is a validation or benchmark shape of the denoising "
                "protocol (spectrageo.evaluate.denoise); training on it would not be held out."
            )
        out.append(m)
    return tuple(out)


@dataclass(frozen=True)
class TrainOptions:
    """Training options shared by both learned denoisers.

    Parameters
    ----------
    epochs : int
    device : {"cpu", "cuda"}
    seed : int
    meshes, levels : sequence, optional
        Training meshes (default :data:`TRAIN_MESHES`; protocol shapes are refused) and noise levels
        (default :data:`TRAIN_LEVELS`).
    per_case, vertex_iter : int
        Samples per (mesh, level); vertex-update iterations (Eq. 4.28) recorded in the weights.
    threads : int, optional
    report : bool
    """

    epochs: int = 10
    device: str = "cpu"
    seed: int = 0
    meshes: tuple[str, ...] | None = None
    levels: tuple[float, ...] | None = None
    per_case: int = 4000
    vertex_iter: int = 20
    threads: int | None = None
    report: bool = True

    def __post_init__(self) -> None:
        check_positive(self.epochs, "epochs", integer=True)
        self._check()
        meshes = check_training_meshes(TRAIN_MESHES if self.meshes is None else self.meshes)
        levels = TRAIN_LEVELS if self.levels is None else tuple(float(x) for x in self.levels)
        object.__setattr__(self, "meshes", meshes)
        object.__setattr__(self, "levels", levels)

    def _check(self) -> None:
        """The model's own checks (between ``epochs`` and ``meshes``)."""


@dataclass(frozen=True)
class DAETrainOptions(TrainOptions):
    """:class:`TrainOptions` of :func:`~spectrageo.learn.train.train_dae`, with ``n_groups`` kappa-means groups per class and ``hidden`` units."""

    n_groups: int = 4
    hidden: int = 32


@dataclass(frozen=True)
class BM3DCNNTrainOptions(TrainOptions):
    """:class:`TrainOptions` of :func:`~spectrageo.learn.train.train_bm3d_cnn` (``epochs`` 4, ``per_case`` 2500).

    Parameters
    ----------
    n_stages : int
        Cascade stages.
    width, kernel, channels : int
        Feature maps, convolution size, image channels (3, 6 or 9).
    batch_size : int
    lr : float
    start : callable, optional
        ``(V_noisy, F) -> V`` applied to every noisy training input: the stages learn to refine it.
    """

    epochs: int = 4
    per_case: int = 2500
    n_stages: int = 3
    width: int = 16
    kernel: int = 5
    channels: int = 6
    batch_size: int = 1024
    lr: float = 3e-3
    start: Callable | None = None

    def _check(self) -> None:
        check_positive(self.n_stages, "n_stages", integer=True)
        if self.channels not in (3, 6, 9):
            raise InvalidInputError(f"`channels` must be 3, 6 or 9; got {self.channels!r}.")


@dataclass(frozen=True)
class FramesTrainOptions:
    """Options of :func:`~spectrageo.learn.dae.train_frames_model` (Section 5.1.3, Fig. 5.38).

    Parameters
    ----------
    temporal : int
        Frames on each side of frame ``t`` in its rows.
    motion : {"auto", "rigid", "none"}
        Motion compensation (docs/decisions.md#learn-motion).
    k, n_groups, hidden, epochs, max_rows : int
        Centroids per row, groups per class, hidden units, epochs, training rows.
    activation : {"tanh", "linear"}
    """

    temporal: int = 2
    motion: str = "auto"
    k: int = IMAGE_COLS
    n_groups: int = 4
    hidden: int = 32
    epochs: int = 10
    max_rows: int = 60000
    activation: str = "tanh"

    def __post_init__(self) -> None:
        check_positive(self.temporal, "temporal", integer=True, allow_zero=True)
        check_positive(self.k, "k", integer=True)
        check_choice(self.motion, "motion", MOTIONS)
