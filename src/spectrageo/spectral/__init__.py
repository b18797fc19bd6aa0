"""Spectral processing: GFT/IGFT, low-pass filtering, orthogonal iterations and submeshes."""

from .gft import Eigenbasis, fix_signs, gft, igft, lowpass_whole

__all__ = ["Eigenbasis", "fix_signs", "gft", "igft", "lowpass_whole"]
