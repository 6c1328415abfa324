"""Number formats shared by the benchmarks' tables."""

from __future__ import annotations

import numpy as np


def fmt_ms(s) -> str:
    """Seconds as milliseconds with three significant digits ("—" for None)."""
    if s is None:
        return "—"
    ms = s * 1e3
    return f"{ms:.0f}" if ms >= 100 else f"{ms:.1f}" if ms >= 10 else f"{ms:.2f}"


def fmt_de(v) -> str:
    """A Delta E ITP with the digits its size needs ("—" for None or non-finite)."""
    if v is None or not np.isfinite(v):
        return "—"
    if v == 0:
        return "0"
    return f"{v:.1e}" if v < 0.01 else f"{v:.3f}" if v < 0.1 else f"{v:.2f}" if v < 10 else \
        f"{v:.1f}"


def write_markdown(path: str, lines: list, rows) -> None:
    """``lines`` (title, notes, the table's header) then ``rows`` as table rows, to ``path``
    (its folder made)."""
    import os
    out = list(lines) + ["| " + " | ".join(map(str, r)) + " |" for r in rows]
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as fh:
        fh.write("\n".join(out) + "\n")
