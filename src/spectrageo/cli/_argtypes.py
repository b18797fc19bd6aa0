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
