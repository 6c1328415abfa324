"""Shared by the benchmark scripts and the tests; not part of the runtime package.

* :mod:`.timing`: the timing rule and Markdown tables.
* :mod:`.photos`: the Poly Haven photographs (fetched once from PyPI).
* :mod:`.scenes`: the appearance benchmark's generated HDR scenes.
* :mod:`.appearance_metrics`: what a person sees (benchmarks/appearance.py, tests).
* :mod:`.validation`: the papers' experiments (Ledda 2004, Fig. 11).
* :mod:`.fit_lmsr`: the fit behind ``ocl_tonemap/data/rgb_to_lmsr.json``.
"""
