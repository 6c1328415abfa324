"""``--quality``: one speed/accuracy setting of every knob (the backend, the bilateral
filter's method and sampling, the flare's method, the display transform's tables),
measured against ``reference`` in ``benchmarks/speed_accuracy.py``."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class QualityTier:
    """One speed/accuracy setting of every knob (``--quality``). Each knob is a
    default: a value the user gives wins. ``operator_options`` apply to the
    operators that declare them, ``effects`` are :class:`EffectSettings` fields.
    The error each tier makes against ``reference`` (Delta E ITP) and its time per
    frame: ``benchmarks/speed_accuracy.py``, ``benchmarks/results/speed_accuracy.md``.
    """

    name: str
    backend: str
    operator_options: tuple          # ((option name, value), ...)
    effects: tuple                   # ((EffectSettings field, value), ...)
    display_encode: str
    description: str

    def options_for(self, declared) -> dict:
        """The tier's operator options among the names an operator ``declared``."""
        declared = set(declared)
        return {k: v for k, v in self.operator_options if k in declared}


#: The tiers. ``balanced`` is the default (today's defaults); ``reference`` is what
#: the others are measured against: the float64 backend, brute-force bilateral
#: filters, the exact flare PSF (FFT), OCIO's CPU processor, no tables.
QUALITY_TIERS = {
    "draft": QualityTier(
        "draft", "opencl",
        (("bilateral", "fast"), ("bilateral_sampling", (1.0,))),
        (("flare_method", "fast"), ("flare_per_octave", 1)), "table",
        "coarsest bilateral grid (1 sample per sigma), fast flare, the display transform "
        "through device tables (durand00's --lut is left off: its kernel is ~1% of the "
        "frame, so the table bought no time and added error; benchmarks/results/"
        "speed_accuracy.md)"),
    "balanced": QualityTier(
        "balanced", "opencl", (), (), "auto",
        "the defaults: bilateral exact when cheap else the grid at 2 samples per sigma, "
        "fast flare, device display tables where they are within one 10-bit code of OCIO"),
    "reference": QualityTier(
        "reference", "reference",
        (("bilateral", "exact"), ("lut", 0)),
        (("flare_method", "exact"),), "ocio",
        "float64 NumPy backend, brute-force bilateral, exact flare PSF, OCIO on the CPU"),
}
QUALITY_NAMES = tuple(QUALITY_TIERS)


def quality_tier(name: str | None) -> QualityTier:
    """The tier called ``name`` (None: ``balanced``)."""
    if name is None:
        return QUALITY_TIERS["balanced"]
    try:
        return QUALITY_TIERS[name]
    except KeyError:
        raise ValueError(f"--quality must be one of {', '.join(QUALITY_NAMES)} "
                         f"(got {name!r})") from None
