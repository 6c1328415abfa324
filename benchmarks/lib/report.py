"""Number formats shared by the benchmarks' tables."""

from __future__ import annotations

import os

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


def cpu_model() -> str:
    """The host CPU's model name (Linux ``/proc/cpuinfo``), else the machine type: the
    peers' ratios move with it (a single-threaded peer gains most from a fast core)."""
    import platform
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def compile_package() -> str:
    """Byte-compile ocl_tonemap's modules where they are, as pip does when it installs
    a wheel, so a timed command starts as an installed one does. In an editable
    install with PYTHONDONTWRITEBYTECODE set (this workplace sets it) every command
    otherwise compiles its ~80 modules again (~0.15 s a start). Returns the note the
    benchmark's table carries."""
    import compileall
    import ocl_tonemap
    compileall.compile_dir(os.path.dirname(ocl_tonemap.__file__), quiet=1)
    return "ocl_tonemap's modules byte-compiled first, as a pip install leaves them"


def write_markdown(path: str, lines: list, rows) -> None:
    """``lines`` (title, notes, the table's header) then ``rows`` as table rows, to ``path``
    (its folder made)."""
    import os
    out = list(lines) + ["| " + " | ".join(map(str, r)) + " |" for r in rows]
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as fh:
        fh.write("\n".join(out) + "\n")


def write_image(path: str, pixels: np.ndarray, **attributes) -> str:
    """(H, W, C) uint8 or float32 ``pixels`` to ``path`` through OIIO (its folder made;
    ``attributes``: spec attributes, such as Compression="jpeg:88"); the absolute path."""
    import os

    import OpenImageIO as oiio
    px = np.ascontiguousarray(pixels)
    kind = oiio.UINT8 if px.dtype == np.uint8 else oiio.FLOAT
    buf = oiio.ImageBuf(oiio.ImageSpec(px.shape[1], px.shape[0], px.shape[2], kind))
    buf.set_pixels(oiio.ROI(), px if kind == oiio.UINT8 else px.astype(np.float32))
    for k, v in attributes.items():
        buf.specmod().attribute(k, v)
    path = os.path.abspath(path)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    if not buf.write(path):
        raise SystemExit(f"{path}: {buf.geterror()}")
    return path


def radiance_env() -> tuple[str, dict]:
    """(bin folder, environment) of Radiance's programs (``ocl_tonemap.io.radiance.tools``),
    or the benchmark ends saying how to install them."""
    from ocl_tonemap.io import radiance
    tools = radiance.tools()
    if tools is None:
        raise SystemExit("Radiance's programs are missing: pip install 'ocl-tonemap[radiance]'")
    return tools


def join(images, axis: int = 1, gap: int = 6) -> np.ndarray:
    """uint8 (H, W, 3) images side by side (``axis`` 1) or stacked (0), white gaps between."""
    out = []
    for k, im in enumerate(images):
        if k:
            shape = list(im.shape)
            shape[axis] = gap
            out.append(np.full(shape, 255, np.uint8))
        out.append(im)
    return np.concatenate(out, axis=axis)
