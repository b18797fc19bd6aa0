"""Argument types shared by the sub-commands."""

from __future__ import annotations

import argparse


def seed_type(text: str) -> int:
    """``--seed`` values: non-negative integers (numpy's generators refuse negative seeds)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a non-negative integer; got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative integer; got {v}")
    return v


def point3_type(text: str) -> tuple[float, float, float]:
    """``X,Y,Z`` values (``--viewpoint``): three finite numbers."""
    try:
        v = tuple(float(x) for x in text.split(","))
    except ValueError:
        v = ()
    if len(v) != 3 or not all(abs(x) < float("inf") for x in v):
        raise argparse.ArgumentTypeError(f"must be X,Y,Z (three finite numbers); got {text!r}")
    return v
