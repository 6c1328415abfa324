"""A chain of colour operations as the Academy/ASC Common LUT Format (CLF v3, SMPTE ST
2136-1) and as OCIO transforms: what an OCIO export writes (``export.py``).

An operation is a tuple:

``("range", lo, hi)``          clamp to [lo, hi] (either None: open);
``("matrix", M, offset)``      x -> M x + offset (3x3, 3);
``("log", P, inverse)``        camera log2 with a linear toe (``lattice.camera_log``
                               parameters (break, slope, offset)), or its inverse;
``("lut1d", columns)``         (L, 3) values over the input domain [0, 1], linear;
``("lut3d", values)``          (n, n, n, 3) values indexed [r, g, b], tetrahedral.

Every one of them is read by OCIO 2.1 and later (CLF v3 Range, Matrix, Log
cameraLinToLog / cameraLogToLin, LUT1D, LUT3D).
"""

from __future__ import annotations

import numpy as np
import PyOpenColorIO as ocio

#: CLF v3's namespace.
NAMESPACE = "urn:AMPAS:CLF:v3.0"


def _values(a: np.ndarray, per_line: int) -> str:
    """Rows of ``per_line`` float32 values (9 significant digits: float32 round-trips)."""
    a = np.asarray(a, np.float32).reshape(-1, per_line)
    line = " ".join(["%.9g"] * per_line) + "\n"
    return (line * a.shape[0]) % tuple(a.astype(np.float64).ravel().tolist())


def _matrix_text(M, offset) -> str:
    M = np.asarray(M, np.float64)
    off = np.asarray(offset, np.float64)
    if np.any(off != 0.0):
        rows = np.concatenate([M, off[:, None]], axis=1)
        dim = "3 4"
    else:
        rows, dim = M, "3 3"
    body = "\n".join(" ".join(f"{v:.17g}" for v in r) for r in rows)
    return (f'  <Matrix inBitDepth="32f" outBitDepth="32f">\n    <Array dim="{dim}">\n{body}\n'
            "    </Array>\n  </Matrix>\n")


def _range_text(lo, hi) -> str:
    parts = []
    if lo is not None:
        parts += [f"    <minInValue>{lo:.17g}</minInValue>", f"    <minOutValue>{lo:.17g}</minOutValue>"]
    if hi is not None:
        parts += [f"    <maxInValue>{hi:.17g}</maxInValue>", f"    <maxOutValue>{hi:.17g}</maxOutValue>"]
    return ('  <Range inBitDepth="32f" outBitDepth="32f" style="Clamp">\n' + "\n".join(parts)
            + "\n  </Range>\n")


def _log_text(P, inverse: bool) -> str:
    beta, k, o = P
    style = "cameraLogToLin" if inverse else "cameraLinToLog"
    return (f'  <Log inBitDepth="32f" outBitDepth="32f" style="{style}">\n'
            f'    <LogParams base="2" linSideSlope="1" linSideOffset="0" '
            f'logSideSlope="{k:.17g}" logSideOffset="{o:.17g}" linSideBreak="{beta:.17g}"/>\n'
            "  </Log>\n")


def to_text(ops, name: str, description: str = "") -> str:
    """The chain as a CLF v3 ProcessList."""
    out = [f'<?xml version="1.0" encoding="UTF-8"?>\n<ProcessList compCLFversion="3" '
           f'xmlns="{NAMESPACE}" id="{_xml(name)}" name="{_xml(name)}">\n']
    if description:
        out.append(f"  <Description>{_xml(description)}</Description>\n")
    for op in ops:
        kind = op[0]
        if kind == "range":
            out.append(_range_text(op[1], op[2]))
        elif kind == "matrix":
            out.append(_matrix_text(op[1], op[2]))
        elif kind == "log":
            out.append(_log_text(op[1], op[2]))
        elif kind == "lut1d":
            cols = np.asarray(op[1])
            out.append(f'  <LUT1D inBitDepth="32f" outBitDepth="32f" interpolation="linear">\n'
                       f'    <Array dim="{cols.shape[0]} 3">\n{_values(cols, 3)}    </Array>\n'
                       "  </LUT1D>\n")
        elif kind == "lut3d":
            v = np.asarray(op[1])
            n = v.shape[0]
            out.append(f'  <LUT3D inBitDepth="32f" outBitDepth="32f" interpolation="tetrahedral">\n'
                       f'    <Array dim="{n} {n} {n} 3">\n{_values(v, 3)}    </Array>\n'
                       "  </LUT3D>\n")
        else:
            raise ValueError(f"unknown CLF operation {kind!r}")
    out.append("</ProcessList>\n")
    return "".join(out)


def _xml(s: str) -> str:
    return (str(s).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace('"', "&quot;"))


def to_transform(ops) -> ocio.GroupTransform:
    """The chain as an OCIO GroupTransform (the same arithmetic as the CLF)."""
    g = ocio.GroupTransform()
    for op in ops:
        kind = op[0]
        if kind == "range":
            r = ocio.RangeTransform()
            if op[1] is not None:
                r.setMinInValue(float(op[1]))
                r.setMinOutValue(float(op[1]))
            if op[2] is not None:
                r.setMaxInValue(float(op[2]))
                r.setMaxOutValue(float(op[2]))
            g.appendTransform(r)
        elif kind == "matrix":
            m = np.eye(4)
            m[:3, :3] = op[1]
            g.appendTransform(ocio.MatrixTransform(
                matrix=[float(a) for a in m.reshape(-1)],
                offset=[float(a) for a in np.asarray(op[2], np.float64)] + [0.0]))
        elif kind == "log":
            beta, k, o = op[1]
            t = ocio.LogCameraTransform(linSideBreak=[beta] * 3, base=2.0, logSideSlope=[k] * 3,
                                        logSideOffset=[o] * 3, linSideSlope=[1.0] * 3,
                                        linSideOffset=[0.0] * 3)
            if op[2]:
                t.setDirection(ocio.TRANSFORM_DIR_INVERSE)
            g.appendTransform(t)
        elif kind == "lut1d":
            cols = np.asarray(op[1], np.float32)
            t = ocio.Lut1DTransform(length=cols.shape[0])
            t.setData(np.ascontiguousarray(cols).reshape(-1))
            g.appendTransform(t)
        elif kind == "lut3d":
            v = np.asarray(op[1], np.float32)
            t = ocio.Lut3DTransform(gridSize=v.shape[0])
            t.setData(np.ascontiguousarray(v).reshape(-1))
            t.setInterpolation(ocio.INTERP_TETRAHEDRAL)
            g.appendTransform(t)
        else:
            raise ValueError(f"unknown CLF operation {kind!r}")
    return g
