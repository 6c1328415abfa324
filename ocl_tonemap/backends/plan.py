"""The per-frame plan: how a frame's stages are executed, not what they compute.

Row bands and their halos (frames larger than the device takes at once), the
bilateral filter's method (exact brute force or the grid) and sampling, and
look-up tables are decided here, in one place, for every operator.
"""

from __future__ import annotations

from dataclasses import dataclass


def row_bands(height: int, width: int, max_pixels: int, halo: int = 0) -> list[tuple[int, int]]:
    """(first row, rows) of the bands that split a ``height`` x ``width`` frame so that a
    band plus ``halo`` rows above and below holds at most ``max_pixels`` pixels
    (at least one row per band)."""
    rows = max(1, min(height, max_pixels // max(width, 1) - 2 * halo))
    return [(y0, min(rows, height - y0)) for y0 in range(0, height, rows)]


@dataclass(frozen=True)
class BilateralSpec:
    """How to filter: ``method`` exact | fast | auto, sigma_s in pixels, grid sampling.

    ``auto`` uses the exact filter when it is cheap (sigma_s <= AUTO_EXACT_SIGMA
    px: on PoCL the grid is slower than brute force at sigma_s = 4 px and 37x
    faster at 12.8, see benchmarks/results/bilateral_ledda04.md) or the grid
    would not fit in memory, and the grid otherwise.
    """

    method: str = "auto"
    q_s: float = 2.0
    q_r: float = 2.0

    AUTO_EXACT_SIGMA = 5.0

    def __post_init__(self):
        if self.method not in ("exact", "fast", "auto"):
            raise ValueError(f"bilateral method must be exact, fast or auto (got {self.method!r})")
        if not (self.q_s >= 0.5 and self.q_r >= 0.5):
            raise ValueError("bilateral sampling rates must be >= 0.5")

    @classmethod
    def parse(cls, method: str, sampling: str | None = None) -> "BilateralSpec":
        if sampling:
            try:
                parts = [float(x) for x in sampling.split(",")]
                q_s, q_r = (parts[0], parts[-1])
            except ValueError:
                raise ValueError(f"bad --bilateral-sampling {sampling!r}: use Q or QS,QR") from None
            return cls(method, q_s, q_r)
        return cls(method)




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
        (("bilateral", "fast"), ("bilateral_sampling", "1")),
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
