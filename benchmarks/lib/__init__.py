"""Shared by the benchmark scripts and the tests; not part of the runtime package.

* :mod:`.outdir`: where a benchmark writes (``--out-dir``, ``--out``; ./benchmark-results).
* :mod:`.timing`: the timing rule, Markdown tables, copy bandwidth, a child's peak memory.
* :mod:`.photos`: the Poly Haven photographs (fetched once from PyPI and Debian) and ``load_photo``.
* :mod:`.scenes`: generated HDR scenes (the appearance scenes and the benchmarks' frames).
* :mod:`.appearance_metrics`: what a person sees (benchmarks/appearance.py, tests).
* :mod:`.validation`: the papers' experiments (Ledda 2004, Fig. 11).
* :mod:`.fit_lmsr`: the fit behind ``ocl_tonemap/data/rgb_to_lmsr.json``.
"""
