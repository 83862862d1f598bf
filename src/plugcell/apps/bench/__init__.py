"""Benchmarks of plugcell (``plugcell bench …``): implementations live here, thin
wrappers in ``benchmarks/``."""
