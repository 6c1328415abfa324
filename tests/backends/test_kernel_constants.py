"""Model constants are written once, in ocl_tonemap/models/: the kernels get them as
-D build options (backends/opencl/constants.py for common.h, each operator's
KERNEL_CONSTANTS for its own file), never typed into kernels/ again. No OpenCL
device needed."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from ocl_tonemap.backends.opencl import constants
from ocl_tonemap.backends.opencl.lmsr import KERNEL_CONSTANTS as KIRK11
from ocl_tonemap.backends.opencl.ledda04 import KERNEL_CONSTANTS as LEDDA04
from ocl_tonemap.backends.opencl.runtime import define_value, kernel_dir
from ocl_tonemap.backends.opencl.visibility import KERNEL_CONSTANTS as VISIBILITY
from ocl_tonemap.models import display, kirk2011, photometry
from ocl_tonemap.operators.pattanaik00 import KERNEL_CONSTANTS as PATTANAIK00

#: Numeric literals of four or more significant digits that may stay in kernels/: none
#: today. An entry is (file, literal as written) and must say why it is not a model
#: constant. (display.cl's 1.5 2^23 rounding trick and 2^-23 mantissa scale are written
#: as hex floats, 0x1.8p23f and 0x1p-23f, which this scan does not count.)
ALLOWED: dict[tuple[str, str], str] = {}

#: The constants each kernel file gets, beside common.h's (constants.COMMON).
PER_FILE = {"ledda04.cl": LEDDA04, "kirk11.cl": KIRK11, "pattanaik00.cl": PATTANAIK00,
            "visibility.cl": VISIBILITY}

_COMMENTS = re.compile(r"/\*.*?\*/|//[^\n]*", re.S)
#: Decimal literals (integer or floating, with an exponent and suffix or not); hex
#: literals (bit masks, hex floats) are not matched.
_NUMBER = re.compile(r"(?<![\w.])(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?[fFuUlL]*(?![\w.])")


def strip_comments(src: str) -> str:
    """The source without /* */ and // comments (line breaks kept: line numbers hold)."""
    return _COMMENTS.sub(lambda m: "\n" * m.group(0).count("\n"), src)


def significant_digits(mantissa: str) -> int:
    """Significant digits of a literal's mantissa: 0.2126 -> 4, 1.0 -> 1, 100.0 -> 1."""
    return len(mantissa.replace(".", "").lstrip("0").rstrip("0"))


def long_literals(src: str):
    """(line, literal) of each numeric literal with four or more significant digits."""
    out = []
    for n, line in enumerate(strip_comments(src).splitlines(), 1):
        for m in _NUMBER.finditer(line):
            if significant_digits(m.group(1)) >= 4:
                out.append((n, m.group(0)))
    return out


def kernel_files():
    return sorted(p for p in kernel_dir().iterdir() if p.suffix in (".cl", ".h"))


def test_the_scan_finds_literals():
    src = """#define M_YR 0.2126f   /* 0.7152f in a comment is not code */
    x = 1.606f * y + 12582912.0f - 2.302585092994046f; // 0.0722f neither
    z = 1e-4f + 0.5f + 100.0f + 0x1.8p23f + 0x7FFFFF + 1.0e10f + 10567;"""
    assert [lit for _, lit in long_literals(src)] == \
        ["0.2126f", "1.606f", "12582912.0f", "2.302585092994046f", "10567"]


def test_no_model_constant_is_typed_into_a_kernel():
    found = [f"kernels/{p.name}:{line}: {lit}" for p in kernel_files()
             for line, lit in long_literals(p.read_text()) if (p.name, lit) not in ALLOWED]
    assert not found, ("numeric literals of 4+ significant digits in kernels/ (a model "
                       "constant? give it from ocl_tonemap/models/ as a build option; "
                       "else allow it in this test, saying why):\n" + "\n".join(found))


def test_allowed_literals_are_still_there():
    for (name, lit), why in ALLOWED.items():
        assert why, (name, lit)
        assert lit in [x for _, x in long_literals((kernel_dir() / name).read_text())], \
            f"kernels/{name} no longer has {lit}: drop it from ALLOWED"


def _f32(text: str) -> np.float32:
    return np.float32(text.rstrip("f"))


@pytest.mark.parametrize("pairs", [constants.COMMON, LEDDA04, KIRK11, PATTANAIK00, VISIBILITY],
                         ids=["common", "ledda04", "kirk11", "pattanaik00", "visibility"])
def test_defines_are_the_models_values_in_float32(pairs):
    names = [k for k, _ in pairs]
    assert len(set(names)) == len(names)
    for k, v in pairs:
        text = define_value(v)
        if isinstance(v, int):
            assert text == str(v), k
        else:
            assert _f32(text) == np.float32(v), (k, text, v)


def test_common_matrix_is_the_models_rgb_to_xyz():
    got = dict(constants.COMMON)
    m = np.array([[_f32(define_value(got[f"M_{r}{c}"])) for c in "RGB"] for r in "XYZ"])
    assert np.array_equal(m, photometry.RGB709_TO_XYZ.astype(np.float32))
    assert np.array_equal(m[1], photometry.Y_WEIGHTS.astype(np.float32))
    assert got["L_MAX"] == photometry.L_MAX
    assert got["NREPAIR"] == len(photometry.RepairCounts.KEYS)
    assert (got["SIGNAL_CEILING"], got["CHANNEL_KNEE"], got["DISPLAY_LINEAR_MAX"]) == \
        (display.SIGNAL_CEILING, display.CHANNEL_KNEE, display.DISPLAY_LINEAR_MAX)


def test_kirk11_closed_form_of_a_inverse():
    """kirk11.cl writes Eq. 11's A^-1 without its zero entries and with its last row
    (0, 1, 1) as d1 + d2: the model's A^-1 must have that form."""
    a = kirk2011.A_INV
    assert a[0, 1] == 0 and a[1, 1] == 0 and a[2, 0] == 0
    assert a[2, 1] == 1 and a[2, 2] == 1
    assert np.allclose(a[:2, [0, 2]], [[-0.5, 0.5], [0.5, 0.5]], rtol=0, atol=1e-15)


def test_defines_are_used_and_not_defined_again_in_kernels():
    """Each generated name is used by its kernel file (no stale entry) and never
    #defined in kernels/ (the build option would be shadowed or redefined)."""
    sources = {p.name: strip_comments(p.read_text()) for p in kernel_files()}
    everything = "\n".join(sources.values())
    for pairs, where in [(constants.COMMON, everything),
                         *((pairs, sources[name]) for name, pairs in PER_FILE.items())]:
        for k, _ in pairs:
            assert re.search(rf"\b{k}\b", where), f"{k} is not used"
            assert not re.search(rf"#\s*define\s+{k}\b", everything), f"{k} is #defined"
