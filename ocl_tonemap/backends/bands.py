"""Row bands: how a frame larger than the device takes at once is split (the band
sizes and their halos; which band size a frame gets is the backend's, from its
device memory or ``--max-memory``)."""

from __future__ import annotations


def row_bands(height: int, width: int, max_pixels: int, halo: int = 0) -> list[tuple[int, int]]:
    """(first row, rows) of the bands that split a ``height`` x ``width`` frame so that a
    band plus ``halo`` rows above and below holds at most ``max_pixels`` pixels
    (at least one row per band)."""
    rows = max(1, min(height, max_pixels // max(width, 1) - 2 * halo))
    return [(y0, min(rows, height - y0)) for y0 in range(0, height, rows)]
