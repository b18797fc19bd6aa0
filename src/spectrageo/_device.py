"""Compute device of the kernels with a GPU path: ``"cpu"`` (numba/numpy, torch never imported),
``"cuda"`` / ``"cuda:N"`` (PyTorch with a visible GPU) or ``"auto"``.
"""

from __future__ import annotations

from typing import Any

from ._errors import InvalidInputError

__all__ = ["DEVICES", "resolve_backend", "resolve_device"]

#: Values accepted by ``device`` arguments and the ``--device`` options of the CLI.
DEVICES = ("cpu", "cuda", "auto")


def _import_torch() -> Any:
    """torch, or None when it cannot be imported."""
    try:
        import torch
    except ImportError:  # a plain install has no torch: the CPU path needs none
        return None
    return torch


def resolve_device(device: str) -> str:
    """The device a kernel runs on: ``"cpu"`` or a CUDA string (``"auto"``: CUDA when torch sees
    a GPU). Raises :class:`InvalidInputError` for an unknown value or an unusable ``"cuda"``.
    """
    if not isinstance(device, str):
        raise InvalidInputError(f"`device` must be one of 'cpu', 'cuda', 'auto'; got {device!r}.")
    dev = device.strip().lower()
    index = None
    if dev.startswith("cuda:"):
        tail = dev[5:]
        if not tail.isdigit():
            raise InvalidInputError(
                f"`device` must be one of 'cpu', 'cuda', 'cuda:N', 'auto'; got {device!r}."
            )
        index, dev = int(tail), "cuda"
    if dev not in DEVICES:
        raise InvalidInputError(
            f"`device` must be one of 'cpu', 'cuda', 'cuda:N', 'auto'; got {device!r}."
        )
    if dev == "cpu":
        return "cpu"
    torch = _import_torch()
    available = torch is not None and bool(torch.cuda.is_available())
    if dev == "auto":
        return "cuda" if available else "cpu"
    if torch is None:
        raise InvalidInputError(
            "`device='cuda'` needs PyTorch with CUDA (pip install torch); torch is not "
            "installed. Use device 'cpu' or 'auto'."
        )
    if not available:
        raise InvalidInputError(
            "`device='cuda'`: no CUDA GPU is available to PyTorch "
            f"(torch {torch.__version__}, CUDA build {torch.version.cuda or 'none'}). "
            "Use device 'cpu' or 'auto'."
        )
    if index is not None:
        count = int(torch.cuda.device_count())
        if index >= count:
            raise InvalidInputError(
                f"`device={device!r}`: only {count} CUDA device(s) are visible."
            )
        return f"cuda:{index}"
    return "cuda"


def resolve_backend(device: Any) -> Any:
    """``"cpu"`` for the numba/numpy path, else the ``torch.device`` of the torch path (a
    ``torch.device``, even a CPU one, always selects torch).
    """
    if isinstance(device, str):
        dev = resolve_device(device)
        if dev == "cpu":
            return "cpu"
        import torch

        return torch.device(dev)
    cls = type(device)
    if cls.__module__ == "torch" and cls.__name__ == "device":
        if device.type == "cuda":
            resolve_device(str(device))  # checks that the GPU is there
        elif device.type != "cpu":
            raise InvalidInputError(f"`device` must be a CPU or CUDA torch.device; got {device!r}.")
        return device
    raise InvalidInputError(
        f"`device` must be one of 'cpu', 'cuda', 'auto' or a torch.device; got {device!r}."
    )
