"""Experiments that hold the operators against measurements of people (issue 34):
dark adaptation (Hecht, Haig & Chase 1937), increment thresholds (Ferwerda 1996's TVI),
acuity (Shlaer 1937) and the Purkinje peak (CIE V and V'). Each runs the tool through its
public API or command line, the same code a user runs; ``benchmarks/psychophysics.py``
writes the table and plots, ``tests/validation/`` checks their shape."""
