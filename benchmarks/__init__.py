"""Benchmarks and evaluation of ocl-tonemap (not shipped in the wheel).

Each script runs from the repository root as ``python -m benchmarks.<name>``
and writes its results into the folder named by ``--out-dir DIR``, by default
``benchmark-results/`` under the current folder; the committed results are
refreshed with ``--out-dir benchmarks/results`` (:mod:`benchmarks.lib.outdir`).
Shared code (timing, photographs, generated scenes, appearance metrics, the
papers' validation experiments, the LMSR fit) is in :mod:`benchmarks.lib`.
"""
