"""Command-line interface ``spectrageo``: a thin layer over the public API."""
