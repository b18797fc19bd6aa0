"""Evaluation harnesses: run methods on datasets and write tables."""
