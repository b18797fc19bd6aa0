"""Seeded fuzz harness of the readers and the codecs: seed files, mutations, a batch driver that
runs ``spectrageo info`` and ``convert`` on each mutant and a classification of the outcomes
(:mod:`.harness`). Used by ``tests/test_fuzz_short.py`` and ``benchmarks/fuzz_long.py``."""
