"""Benchmarks and evaluation of ocl-tonemap (not shipped in the wheel).

Each script runs from the repository root as ``python -m benchmarks.<name>``
and writes its results to ``benchmarks/results/``. Shared code (timing,
photographs, generated scenes, appearance metrics, the papers' validation
experiments, the LMSR fit) is in :mod:`benchmarks.lib`.
"""
