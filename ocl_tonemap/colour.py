"""Colour management through OpenColorIO.

Config resolution: ``--colorconfig`` > ``$OCIO`` > ``ocio://default``. The
bundled config is available by name (``ocl-tonemap`` or ``bundled``); any
``ocio://`` built-in URI and any file path work too. Never silently a raw
config: an unreadable config is an error.

Input colour (:func:`resolve_input`), first that applies:

1. ``--iscolorspace``;
2. the file's ``oiio:ColorSpace`` when the config knows it, else when OCIO's
   built-in config knows it (OIIO's colour interop IDs, ``lin_rec709_scene``...);
3. the EXR ``chromaticities`` attribute: a matrix to the working space
   (Bradford adaptation when the white is not D65, as OCIO's configs do);
4. a file rule of a config the user chose (a file, not an ``ocio://``
   built-in) when a rule other than the config's default rule matches;
5. otherwise scene-linear Rec.709, OIIO's and OpenEXR's convention for a file
   that says nothing -- reported once per run as an assumption.

The built-in configs' file rules (``*.exr -> ACES2065-1`` in ``ocio://default``)
are the ACES reference pipeline's convention, not knowledge about the file,
so they are not used. Pixels are converted to the working space, linear
BT.709/D65, where the papers' luminance formulas hold.

Output: the operators produce display-linear BT.709 light. Integer formats
get OCIO's display/view encoding (the config's un-tone-mapped view, so no
second tone curve); float outputs (EXR) default to display-linear light in
the config's linear colourspace with the display's primaries
(:meth:`ColourPipeline.linear_output`), tagged with it.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import PyOpenColorIO as ocio

BUNDLED_NAMES = ("ocl-tonemap", "bundled")
WORKING_CANDIDATES = ("lin_rec709", "Linear Rec.709 (sRGB)", "Utility - Linear - sRGB",
                      "lin_srgb", "Linear BT.709")
#: Views that only encode (no tone curve), in order of preference.
PLAIN_VIEWS = ("Un-tone-mapped", "Video (colorimetric)", "Standard", "Display-linear")
USE_DISPLAY_NAME = "<USE_DISPLAY_NAME>"


class ColourError(ValueError):
    """A colour-management request that cannot be honoured."""


def bundled_config_path() -> Path:
    from .resources import package_data_dir
    return package_data_dir("ocio_configs", "ocl_tonemap.ocio") / "ocl_tonemap.ocio"


def resolve_config_source(colorconfig: str | None = None) -> str:
    """Which config to load, as a path or ocio:// URI (see module doc)."""
    src = colorconfig or os.environ.get("OCIO") or "ocio://default"
    if src in BUNDLED_NAMES:
        return str(bundled_config_path())
    return src


def is_builtin_source(src: str) -> bool:
    """An ``ocio://`` built-in config (its file rules are not the user's)."""
    return str(src).startswith("ocio://")


def load_config(colorconfig: str | None = None) -> ocio.Config:
    src = resolve_config_source(colorconfig)
    try:
        cfg = ocio.Config.CreateFromFile(src)
        cfg.validate()
    except Exception as exc:  # OCIO raises its own Exception type
        raise ColourError(f"cannot load OCIO config {src!r}: {exc}") from exc
    return cfg


def _has_cs(cfg: ocio.Config, name: str | None) -> bool:
    return bool(name) and cfg.getColorSpace(name) is not None


def working_space(cfg: ocio.Config) -> str:
    """The config's name for linear BT.709/D65."""
    for name in WORKING_CANDIDATES:
        cs = cfg.getColorSpace(name)
        if cs is not None:
            return cs.getName()
    raise ColourError("the OCIO config has no linear BT.709 colourspace (looked for "
                      + ", ".join(WORKING_CANDIDATES) + "); use the bundled config "
                      "(--colorconfig ocl-tonemap) or add one")


def input_colorspace(cfg: ocio.Config, path: str | None, file_cs: str | None,
                     override: str | None) -> tuple[str, str]:
    """(colourspace, why) by the precedence of the OCIO names only (override, file
    metadata, file rules, the scene_linear role); the CLI uses :func:`resolve_input`."""
    if override:
        if not _has_cs(cfg, override):
            raise ColourError(f"--iscolorspace {override!r} is not in the OCIO config")
        return cfg.getColorSpace(override).getName(), "--iscolorspace"
    if _has_cs(cfg, file_cs):
        return cfg.getColorSpace(file_cs).getName(), "file oiio:ColorSpace"
    if path and not cfg.filepathOnlyMatchesDefaultRule(path):
        cs = cfg.getColorSpaceFromFilepath(path)
        if isinstance(cs, tuple):        # OCIO >= 2.x Python: (name, rule index)
            cs = cs[0]
        return cs, "config file rules"
    role = cfg.getRoleColorSpace("scene_linear") if hasattr(cfg, "getRoleColorSpace") else None
    if not role:
        cs = cfg.getColorSpace("scene_linear")
        role = cs.getName() if cs is not None else None
    if not role:
        raise ColourError("no input colourspace: the file names none the config knows, "
                          "and the config has no scene_linear role; pass --iscolorspace")
    return role, "scene_linear role"


#: EXR/CIE chromaticities (rx, ry, gx, gy, bx, by, wx, wy) of the working space.
REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
#: Bradford cone response matrix (Lam 1985), the CAT of OCIO's ACES configs.
BRADFORD = np.array([[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367],
                     [0.0389, -0.0685, 1.0296]])


def chromaticities_to_xyz(chrom) -> np.ndarray:
    """RGB -> XYZ matrix (float64) of primaries and white given as xy chromaticities
    (white normalised to Y = 1), SMPTE RP 177."""
    c = [float(v) for v in chrom]
    if len(c) != 8 or not all(np.isfinite(c)):
        raise ColourError(f"chromaticities need 8 finite numbers (got {chrom!r})")
    xy = np.array(c).reshape(4, 2)
    if np.any(xy[:3, 1] == 0) or xy[3, 1] <= 0:       # (AP0's blue primary has y < 0)
        raise ColourError(f"chromaticities with y = 0 or a white with y <= 0: {chrom!r}")
    XYZ = np.stack([xy[:, 0] / xy[:, 1], np.ones(4), (1.0 - xy.sum(axis=1)) / xy[:, 1]], axis=1)
    P = XYZ[:3].T
    if abs(np.linalg.det(P)) < 1e-9:
        raise ColourError(f"chromaticities have collinear primaries: {chrom!r}")
    return P * np.linalg.solve(P, XYZ[3])


def xyz_to_chromaticities(M: np.ndarray) -> tuple:
    """Inverse of :func:`chromaticities_to_xyz`: the xy of the columns and of their sum."""
    cols = [M[:, 0], M[:, 1], M[:, 2], M.sum(axis=1)]
    return tuple(float(v) for c in cols for v in (c[0] / c.sum(), c[1] / c.sum()))


def chromaticities_to_working(chrom) -> np.ndarray:
    """Matrix from RGB with these chromaticities to linear BT.709/D65, with a
    Bradford adaptation from the file's white to D65."""
    from .models.photometry import RGB709_TO_XYZ
    M = chromaticities_to_xyz(chrom)
    src_w = M.sum(axis=1)
    dst_w = RGB709_TO_XYZ.sum(axis=1)
    cat = np.linalg.inv(BRADFORD) @ np.diag((BRADFORD @ dst_w) / (BRADFORD @ src_w)) @ BRADFORD
    return np.linalg.inv(RGB709_TO_XYZ) @ cat @ M


def is_rec709(chrom, tol: float = 1e-3) -> bool:
    return bool(np.max(np.abs(np.asarray(chrom, np.float64) - REC709_CHROMATICITIES)) < tol)


@dataclass(frozen=True)
class InputColour:
    """How one input file's RGB becomes working-space RGB.

    kind : ``"ocio"`` (processor from ``colorspace`` of ``config``), ``"matrix"``
        (``matrix`` from the EXR chromaticities) or ``"working"`` (as it is).
    why : where the decision came from, for the log and the ``ocltm:`` metadata.
    assumed : nothing in the file or on the command line said it.
    """

    kind: str
    colorspace: str
    why: str
    assumed: bool = False
    matrix: tuple | None = None
    builtin: bool = False       # the name comes from OCIO's built-in config

    def describe(self) -> str:
        return f"{self.colorspace} ({self.why})"


_BUILTIN: dict = {}


def builtin_config() -> ocio.Config:
    """OCIO's built-in default config (knows OIIO's colour interop IDs)."""
    if "cfg" not in _BUILTIN:
        _BUILTIN["cfg"] = ocio.Config.CreateFromFile("ocio://default")
    return _BUILTIN["cfg"]


def resolve_input(cfg: ocio.Config, path: str | None, file_cs: str | None,
                  override: str | None, chromaticities=None,
                  rules_from_user_config: bool = True) -> InputColour:
    """The input colour of one file, by the precedence in the module doc."""
    work = working_space(cfg)
    if override:
        if not _has_cs(cfg, override):
            raise ColourError(f"--iscolorspace {override!r} is not in the OCIO config")
        return InputColour("ocio", cfg.getColorSpace(override).getName(), "--iscolorspace")
    unknown = ""
    if file_cs:
        if _has_cs(cfg, file_cs):
            return InputColour("ocio", cfg.getColorSpace(file_cs).getName(),
                               "file oiio:ColorSpace")
        b = builtin_config()
        if _has_cs(b, file_cs):
            return InputColour("ocio", b.getColorSpace(file_cs).getName(),
                               f"file oiio:ColorSpace {file_cs!r}, OCIO built-in config",
                               builtin=True)
        unknown = f"the file's oiio:ColorSpace {file_cs!r} is unknown; "
    if chromaticities is not None:
        try:
            if is_rec709(chromaticities):
                return InputColour("working", work, unknown + "EXR chromaticities: Rec.709/D65")
            M = chromaticities_to_working(chromaticities)
        except ColourError as exc:
            unknown += f"ignored bad chromaticities ({exc}); "
        else:
            return InputColour("matrix", "RGB with chromaticities " + ",".join(
                f"{v:.4g}" for v in chromaticities), unknown + "EXR chromaticities",
                matrix=tuple(map(tuple, M)))
    if path and rules_from_user_config and not cfg.filepathOnlyMatchesDefaultRule(path):
        cs = cfg.getColorSpaceFromFilepath(path)
        if isinstance(cs, tuple):        # OCIO >= 2.x Python: (name, rule index)
            cs = cs[0]
        if _has_cs(cfg, cs):
            return InputColour("ocio", cfg.getColorSpace(cs).getName(), unknown + "config file rules")
    return InputColour("working", work, unknown + "untagged: scene-linear Rec.709, the "
                       "OIIO/OpenEXR convention; --iscolorspace to override", assumed=True)


def default_display(cfg: ocio.Config) -> str:
    return cfg.getDefaultDisplay()


def default_view(cfg: ocio.Config, display: str) -> str:
    views = list(cfg.getViews(display))
    for v in PLAIN_VIEWS:
        if v in views:
            return v
    raise ColourError(f"display {display!r} has no un-tone-mapped view (looked for "
                      f"{', '.join(PLAIN_VIEWS)}); choose one with --view from: {', '.join(views)}")


def list_displays(cfg: ocio.Config) -> list[tuple[str, list[str]]]:
    return [(d, list(cfg.getViews(d))) for d in cfg.getDisplays()]


class ColourPipeline:
    """OCIO processors for one run: input -> working, working -> display."""

    def __init__(self, cfg: ocio.Config, display: str | None = None, view: str | None = None):
        self.cfg = cfg
        self.working = working_space(cfg)
        displays = list(cfg.getDisplays())
        self.display = display or default_display(cfg)
        if self.display not in displays:
            raise ColourError(f"display {self.display!r} not in the OCIO config; "
                              f"available: {', '.join(displays)}")
        self.view = view or default_view(cfg, self.display)
        if self.view not in list(cfg.getViews(self.display)):
            raise ColourError(f"view {self.view!r} not in display {self.display!r}; available: "
                              + ", ".join(cfg.getViews(self.display)))
        self._in_procs: dict[str, object] = {}
        proc = cfg.getProcessor(self.working, self.display, self.view, ocio.TRANSFORM_DIR_FORWARD)
        self._out = proc.getDefaultCPUProcessor()

    @property
    def output_colorspace(self) -> str:
        name = self.cfg.getDisplayViewColorSpaceName(self.display, self.view)
        return self.display if (not name or name == USE_DISPLAY_NAME) else name

    @property
    def view_is_plain(self) -> bool:
        return self.view in PLAIN_VIEWS or self.view.lower() == "raw"

    def to_working(self, pixels: np.ndarray, src_cs: str) -> np.ndarray:
        """Convert (H, W, C>=3) float32 pixels from ``src_cs`` in place; returns them."""
        if self.cfg.getColorSpace(src_cs).getName() == self.working:
            return pixels
        proc = self._in_procs.get(src_cs)
        if proc is None:
            proc = self.cfg.getProcessor(src_cs, self.working).getDefaultCPUProcessor()
            self._in_procs[src_cs] = proc
        _apply(proc, pixels)
        return pixels

    def convert_input(self, pixels: np.ndarray, ic: InputColour) -> np.ndarray:
        """Working-space RGB of (H, W, C>=3) float32 ``pixels`` described by ``ic``
        (converted in place where possible; returns the array)."""
        if ic.kind == "working":
            return pixels
        if ic.kind == "matrix":
            M = np.asarray(ic.matrix, np.float32)
            pixels[..., :3] = pixels[..., :3] @ M.T
            return pixels
        if not ic.builtin:
            return self.to_working(pixels, ic.colorspace)
        key = ("builtin", ic.colorspace)
        proc = self._in_procs.get(key)
        if proc is None:
            b = builtin_config()
            proc = b.getProcessor(ic.colorspace, working_space(b)).getDefaultCPUProcessor()
            self._in_procs[key] = proc
        _apply(proc, pixels)
        return pixels

    def _matrix_from_working(self, cs: str) -> np.ndarray | None:
        """The 3x3 matrix working -> ``cs`` when OCIO's transform is linear, else None."""
        try:
            proc = self.cfg.getProcessor(self.working, cs).getDefaultCPUProcessor()
        except Exception:  # noqa: BLE001 -- OCIO raises its own Exception type
            return None
        probe = np.array([[[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, 0.25, 2.0], [4.0, 8.0, 0.5]]],
                         np.float32)
        _apply(proc, probe)
        M = probe[0, :3].T.astype(np.float64)
        for v, got in ((np.array([0.5, 0.25, 2.0]), probe[0, 3]),
                       (np.array([4.0, 8.0, 0.5]), probe[0, 4])):
            if not np.allclose(M @ v, got, rtol=1e-4, atol=1e-5):
                return None
        return M if np.all(np.isfinite(M)) and abs(np.linalg.det(M)) > 1e-6 else None

    def linear_output(self) -> tuple[str, np.ndarray]:
        """(name, matrix working -> it) of the colourspace that holds display-linear
        light in the display's primaries: the config's linear colourspace whose
        primaries and white match the display's (display-linear encodings first);
        the working space when the config has none."""
        if getattr(self, "_linear_out", None) is not None:
            return self._linear_out
        from .models.photometry import RGB709_TO_XYZ
        D = self.display_primaries()
        target = xyz_to_chromaticities(RGB709_TO_XYZ @ D)
        best = None
        for name in self.cfg.getColorSpaceNames():
            cs = self.cfg.getColorSpace(name)
            if cs is None or cs.isData():
                continue
            enc = cs.getEncoding() if hasattr(cs, "getEncoding") else ""
            if enc not in ("", "scene-linear", "display-linear"):
                continue
            M = self._matrix_from_working(name)
            if M is None:
                continue
            chrom = xyz_to_chromaticities(RGB709_TO_XYZ @ np.linalg.inv(M))
            if max(abs(a - b) for a, b in zip(chrom, target)) > 2e-3:
                continue
            rank = (0 if enc == "display-linear" else 1 if enc == "scene-linear" else 2,
                    0 if name == self.working else 1)
            if best is None or rank < best[0]:
                best = (rank, name, M)
        if best is None:
            self._linear_out = (self.working, np.eye(3))
        else:
            self._linear_out = (best[1], best[2])
        return self._linear_out

    def linear(self, display_linear: np.ndarray) -> np.ndarray:
        """Display-linear working RGB -> display-linear light in :meth:`linear_output`'s
        colourspace (new array, through OCIO)."""
        name, M = self.linear_output()
        out = np.array(display_linear, dtype=np.float32, copy=True, order="C")
        if name != self.working:
            key = ("out", name)
            proc = self._in_procs.get(key)
            if proc is None:
                proc = self.cfg.getProcessor(self.working, name).getDefaultCPUProcessor()
                self._in_procs[key] = proc
            _apply(proc, out)
        return out

    def output_chromaticities(self, encoded: bool) -> tuple:
        """EXR chromaticities of what is written: the display's primaries (encoded
        output), or those of the linear output colourspace."""
        from .models.photometry import RGB709_TO_XYZ
        if encoded:
            return xyz_to_chromaticities(RGB709_TO_XYZ @ self.display_primaries())
        _, M = self.linear_output()
        return xyz_to_chromaticities(RGB709_TO_XYZ @ np.linalg.inv(M))

    def display_primaries(self) -> np.ndarray:
        """(3, 3): column c is the working-space linear RGB of the display's primary c
        (through the inverse display/view transform), scaled so that the columns
        sum to luminance 1. For a BT.709 display this is the identity."""
        proc = self.cfg.getProcessor(self.working, self.display, self.view,
                                     ocio.TRANSFORM_DIR_INVERSE).getDefaultCPUProcessor()
        codes = np.array([[[0.5, 0, 0], [0, 0.5, 0], [0, 0, 0.5], [0, 0, 0]]], np.float32)
        _apply(proc, codes)
        D = (codes[0, :3] - codes[0, 3]).T.astype(np.float64)
        from .models.photometry import Y_WEIGHTS
        y = float(Y_WEIGHTS @ D.sum(axis=1))
        if not (np.all(np.isfinite(D)) and y > 0):
            return np.eye(3)
        return D / y

    def encode(self, display_linear: np.ndarray) -> np.ndarray:
        """Display-linear working-space RGB -> display encoding (new array)."""
        out = np.array(display_linear, dtype=np.float32, copy=True, order="C")
        _apply(self._out, out)
        return out

    #: The device table :meth:`encode_fast` uses (:meth:`set_display_encode`); None: OCIO.
    device_table = None
    display_encode_note = "display encoding: OCIO CPU processor"

    def display_table(self, form: str = "auto", size_3d: int = 65) -> DisplayTable:
        """This pipeline's display/view transform baked into a table (once per arguments;
        see :func:`bake_display_table`)."""
        key = (form, size_3d)
        cache = self.__dict__.setdefault("_display_tables", {})
        if key not in cache:
            proc = self.cfg.getProcessor(self.working, self.display, self.view,
                                         ocio.TRANSFORM_DIR_FORWARD)
            cache[key] = cached_display_table(proc, form, size_3d,
                                              description=f"{self.display} / {self.view}")
        return cache[key]

    def set_display_encode(self, mode: str = "auto", backend: str = "opencl",
                           device: str | None = None) -> str:
        """Choose how :meth:`encode_fast` encodes (``--display-encode``): ``"table"`` through
        the baked table on the OpenCL device, ``"ocio"`` through OCIO's CPU processor,
        ``"auto"``: the table when the OpenCL backend is used and its self-check error is
        below one 10-bit code value, else OCIO. Returns what was chosen and why."""
        if mode not in DISPLAY_ENCODE_MODES:
            raise ColourError(f"--display-encode must be one of {', '.join(DISPLAY_ENCODE_MODES)} "
                              f"(got {mode!r})")
        self.device_table = None
        if mode == "ocio" or (mode == "auto" and backend != "opencl"):
            self.display_encode_note = ("display encoding: OCIO CPU processor ("
                                        + ("--display-encode ocio)" if mode == "ocio"
                                           else f"backend {backend})"))
            return self.display_encode_note
        try:
            table = self.display_table()
            if mode == "auto" and not table.within_10bit:
                self.display_encode_note = (
                    f"display encoding: OCIO CPU processor (the baked table is off by up to "
                    f"{table.max_error * 1023:.3g} 10-bit code values: {table.describe()})")
                return self.display_encode_note
            if table.kind != "identity":
                from .backends.opencl.display import DeviceDisplayTable
                self.device_table = DeviceDisplayTable(table, device=device)
        except Exception as exc:  # noqa: BLE001 -- auto: OCIO is always there
            if mode == "table":
                raise
            self.display_encode_note = (f"display encoding: OCIO CPU processor (no device "
                                        f"table: {exc})")
            return self.display_encode_note
        self.display_encode_note = "display encoding: " + table.describe()
        return self.display_encode_note

    def device_output_encoding(self, u8: bool, runtime):
        """:meth:`encode_fast` (``u8`` as there) as a ``DeviceOutputEncoding`` for an
        operator whose output is on ``runtime``'s device (an OpenCL runtime), so that the
        table runs there and only code values come back; None where :meth:`encode_fast`
        uses OCIO, or the table is in another context."""
        table = self.device_table
        if table is None or runtime is None or \
                getattr(runtime, "context", None) != table.rt.context:
            return None
        cache = self.__dict__.setdefault("_device_encodings", {})
        enc = cache.get(bool(u8))
        if enc is None or enc.table is not table:
            from .backends.opencl.display import DeviceOutputEncoding
            cache[bool(u8)] = enc = DeviceOutputEncoding(table, u8)
        return enc

    def encode_fast(self, display_linear: np.ndarray, u8: bool = False) -> np.ndarray:
        """:meth:`encode` through the device table chosen by :meth:`set_display_encode` (new
        array; RGB encoded, a 4th channel kept), or through OCIO when none was chosen.
        ``u8``: 8-bit code values quantised on the device as OIIO quantises them when
        it writes, where a device table encodes (else float code values)."""
        table = self.device_table
        if table is None:
            return self.encode(display_linear)
        if u8 and display_linear.shape[-1] in (3, 4):
            return table.encode(display_linear, u8=True)
        return table.encode(display_linear)


def _apply(cpu_proc, pixels: np.ndarray) -> None:
    """Apply an OCIO CPU processor to the RGB of a C-contiguous float32 array in place."""
    if pixels.dtype != np.float32 or not pixels.flags.c_contiguous:
        raise TypeError("OCIO processing needs C-contiguous float32 pixels")
    h, w, c = pixels.shape
    if c == 3:
        cpu_proc.applyRGB(pixels)
    elif c == 4:
        cpu_proc.applyRGBA(pixels)
    else:
        rgb = np.ascontiguousarray(pixels[..., :3])
        cpu_proc.applyRGB(rgb)
        pixels[..., :3] = rgb


# --- the display transform baked into tables (kernels/display.cl) ----------------------------

#: One 10-bit code value: the error bound the baked display tables are held to.
CODE_10BIT = 1.0 / 1023.0
#: ``--display-encode`` choices.
DISPLAY_ENCODE_MODES = ("auto", "table", "ocio")
#: The tables' input shapers, both ~log2(1 + |v|/eps) (eps a power of two, per table
#: form, chosen by measurement: docs/models.md):
#: "bits" (1D tables): from the float32 bits of |v| + eps = 2^e (1 + m), m in [0, 1),
#: s = sign(v) (e - log2(eps) + m (4 - m) / 3): smooth (C1), equal to log2(1 + |v|/eps)
#: at every power of two of |v| + eps and within 0.01 between them; a few integer and
#: multiply-add operations on the device, 2.5x faster than log2 on PoCL;
#: "log2" (3D tables): s = sign(v) log2(1 + |v|/eps) exactly (half the 3D error of
#: "bits" at the same lattice size: the gathers, not the log, dominate a 3D lookup).
SHAPER_EPS_1D = 2.0 ** -24
SHAPER_EPS_3D = (2.0 ** -17, 2.0 ** -14, 2.0 ** -20)
#: 1D tables: nodes per octave of |v| + eps (every node interval lies in one octave).
NODES_PER_OCTAVE_1D = 128
_MANT = float(2 ** 23)


def _eps_exponent(eps: float) -> int:
    e = math.log2(eps)
    if e != int(e) or not -126 < e < 100:
        raise ValueError(f"the shaper's eps must be a power of two (got {eps!r})")
    return int(e)


def shaper(v, eps: float, kind: str = "bits") -> np.ndarray:
    """A table input shaper (see SHAPER_EPS_1D) of float32 ``v``, in float64, as
    kernels/display.cl computes it in float32."""
    v32 = np.asarray(v, np.float32)
    if kind == "log2":
        with np.errstate(invalid="ignore"):
            s = np.log2(np.abs(v32.astype(np.float64)) + eps) - _eps_exponent(eps)
        s = np.where(np.isnan(s), np.inf, s)
    else:
        with np.errstate(invalid="ignore"):
            a = (np.abs(v32) + np.float32(eps)).astype(np.float32)
        bits = a.view(np.int32).astype(np.int64)
        m = (bits & 0x7FFFFF) / _MANT
        s = ((bits >> 23) - 127 - _eps_exponent(eps)) + m * (4.0 - m) / 3.0
    return np.where(v32 < 0, -s, s)


def shaper_inverse(s, eps: float, kind: str = "bits") -> np.ndarray:
    """v with shaper(v) = s (float64)."""
    s = np.asarray(s, np.float64)
    a = np.abs(s)
    if kind == "log2":
        return np.copysign(eps * np.expm1(a * np.log(2.0)), s)
    j = np.floor(a)
    m = 2.0 - np.sqrt(np.maximum(4.0 - 3.0 * (a - j), 0.0))
    return np.copysign(np.exp2(j + _eps_exponent(eps)) * (1.0 + m) - eps, s)


def display_probe_set(n_random: int = 100_000, seed: int = 0, vmax: float | None = None,
                      n_axis: int = 4096) -> np.ndarray:
    """(N, 3) float32 working-space RGB spread over the display-linear domain [0, vmax]:
    the grey axis, the primaries and secondaries (dense: log-spaced from 1e-10, linear
    near 0 and over the range), ``n_random`` triples with log-uniform peak in
    [1e-8, vmax] and random chromaticity (a tenth with a zero channel: saturated),
    and saturated colours (one channel at vmax/4..vmax, the others far below)."""
    from .models.display import DISPLAY_LINEAR_MAX
    vmax = float(DISPLAY_LINEAR_MAX if vmax is None else vmax)
    rng = np.random.default_rng(seed)
    v = np.concatenate([[0.0, vmax], np.logspace(-10, np.log10(vmax), n_axis),
                        np.linspace(0.0, 1e-3, n_axis // 4), np.linspace(0.0, 2.0, n_axis // 4),
                        np.linspace(0.0, vmax, n_axis // 4)])
    dirs = np.array([(1, 1, 1), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, 0, 1), (0, 1, 1)],
                    np.float64)
    parts = [v[:, None, None] * dirs[None]]
    peak = 2.0 ** rng.uniform(np.log2(1e-8), np.log2(vmax), n_random)
    w = rng.uniform(0.0, 1.0, (n_random, 3)) ** rng.choice([0.5, 1.0, 3.0, 8.0], (n_random, 1))
    w[rng.uniform(size=(n_random, 3)) < 0.1] = 0.0
    parts.append(w / np.maximum(w.max(axis=1, keepdims=True), 1e-300) * peak[:, None])
    n_sat = max(n_random // 10, 64)
    sat = rng.uniform(0.0, 1e-3, (n_sat, 3)) * rng.uniform(0.0, 1.0, (n_sat, 1))
    sat[np.arange(n_sat), rng.integers(0, 3, n_sat)] = rng.uniform(vmax / 4, vmax, n_sat)
    parts.append(sat)
    rgb = np.concatenate([p.reshape(-1, 3) for p in parts])
    return np.clip(rgb, 0.0, vmax).astype(np.float32)


@dataclass(frozen=True, eq=False)
class DisplayTable:
    """The forward display/view transform of a config, baked over [0, vmax]^3.

    kind : ``"identity"`` (OCIO's processor is a no-op), ``"1d"`` (per-channel
        separable: ``matrix``/``offset`` then one curve per channel) or ``"3d"``
        (a lattice of ``size``^3 RGB triples, tetrahedral interpolation).
    The table input is ``s = shaper(matrix @ rgb + offset, eps, shaper)`` per channel (3D:
    ``matrix`` is the identity), clamped to [s_lo, s_hi], sampled at ``size`` equally
    spaced points (``table`` is float64: (size, 3), or (size, size, size, 3) indexed
    [r, g, b]); values outside the baked domain read the nearest edge.
    max_error, p999_error : the bake-time self-check against OCIO's CPU processor on
    :func:`display_probe_set` (``probes`` triples), in code values (x 1023 for 10-bit).
    """

    kind: str
    matrix: np.ndarray
    offset: np.ndarray
    eps: float
    s_lo: float
    s_hi: float
    table: np.ndarray
    shaper: str = "bits"
    description: str = ""
    vmax: float = 100.0
    max_error: float = 0.0
    p999_error: float = 0.0
    probes: int = 0

    @property
    def size(self) -> int:
        return int(self.table.shape[0]) if self.kind != "identity" else 0

    @property
    def within_10bit(self) -> bool:
        """The self-check's largest error is below one 10-bit code value."""
        return self.max_error < CODE_10BIT

    def describe(self) -> str:
        if self.kind == "identity":
            return f"{self.description}: identity (no table)"
        form = (f"matrix + 3 x {self.size}-point 1D table" if self.kind == "1d"
                else f"{self.size}^3 3D table, tetrahedral")
        return (f"{self.description}: {form}, {self.shaper} shaper, eps "
                f"2^{math.log2(self.eps):g}; self-check vs OCIO on {self.probes} RGB: "
                f"max {self.max_error * 1023:.3g}, "
                f"99.9% {self.p999_error * 1023:.3g} 10-bit code values")

    def indices(self, rgb) -> np.ndarray:
        """Fractional table coordinates in [0, size - 1] of (..., 3) RGB (float64)."""
        x = np.asarray(rgb, np.float64)[..., :3]
        if self.kind == "1d":
            x = x @ self.matrix.T + self.offset
        scale = (self.size - 1) / (self.s_hi - self.s_lo)
        return np.clip((shaper(x, self.eps, self.shaper) - self.s_lo) * scale, 0.0, self.size - 1)

    def apply(self, rgb) -> np.ndarray:
        """The float64 reference of the table lookup (what kernels/display.cl computes in
        float32): (..., 3) RGB -> (..., 3) code values."""
        x = np.asarray(rgb, np.float64)[..., :3]
        if self.kind == "identity":
            return x.copy()
        f = self.indices(x)
        shape = f.shape
        f = f.reshape(-1, 3)
        i = np.minimum(np.floor(f).astype(np.int64), self.size - 2)
        t = f - i
        T = self.table
        if self.kind == "1d":
            ch = np.arange(3)
            lo, hi = T[i, ch], T[i + 1, ch]
            return (lo + t * (hi - lo)).reshape(shape)
        return _tetrahedral(T, i, t).reshape(shape)

    def error_against(self, cpu_proc, rgb) -> tuple[float, float]:
        """(max, 99.9th percentile) over ``rgb`` (N, 3) of the largest channel's |table -
        OCIO| in code values."""
        x = np.ascontiguousarray(np.asarray(rgb, np.float32).reshape(1, -1, 3))
        ref = x.copy()
        _apply(cpu_proc, ref)
        e = np.abs(self.apply(x[0]) - ref[0].astype(np.float64))
        e = np.where(np.isfinite(e), e, np.inf).max(axis=1)
        return float(e.max()), float(np.percentile(e, 99.9))


def _tetrahedral(T: np.ndarray, i: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Tetrahedral interpolation in the (N, N, N, 3) lattice ``T`` at cells ``i`` (M, 3),
    fractions ``t`` (M, 3) (float64; the same six tetrahedra as kernels/display.cl)."""
    r, g, b = t[:, 0:1], t[:, 1:2], t[:, 2:3]
    ir, ig, ib = i[:, 0], i[:, 1], i[:, 2]

    def c(a, bb, cc):
        return T[ir + a, ig + bb, ib + cc]
    c000, c111 = c(0, 0, 0), c(1, 1, 1)
    c100, c010, c001 = c(1, 0, 0), c(0, 1, 0), c(0, 0, 1)
    c110, c101, c011 = c(1, 1, 0), c(1, 0, 1), c(0, 1, 1)
    rg, gb, rb = r >= g, g >= b, r >= b
    out = np.where(rg & gb, c000 + r * (c100 - c000) + g * (c110 - c100) + b * (c111 - c110), 0.0)
    out = np.where(rg & ~gb & rb, c000 + r * (c100 - c000) + b * (c101 - c100)
                   + g * (c111 - c101), out)
    out = np.where(rg & ~gb & ~rb, c000 + b * (c001 - c000) + r * (c101 - c001)
                   + g * (c111 - c101), out)
    out = np.where(~rg & rb, c000 + g * (c010 - c000) + r * (c110 - c010)
                   + b * (c111 - c110), out)
    out = np.where(~rg & ~rb & gb, c000 + g * (c010 - c000) + b * (c011 - c010)
                   + r * (c111 - c011), out)
    out = np.where(~rg & ~gb, c000 + b * (c001 - c000) + g * (c011 - c001)
                   + r * (c111 - c011), out)
    return out


def _leading_matrix(proc) -> tuple[np.ndarray, np.ndarray]:
    """(M, offset) of the matrices that open OCIO's optimized transform (identity if none)."""
    M, o = np.eye(3), np.zeros(3)
    try:
        group = proc.getOptimizedProcessor(ocio.OPTIMIZATION_DEFAULT).createGroupTransform()
    except Exception:  # noqa: BLE001 -- OCIO raises its own Exception type
        return M, o
    for t in group:
        if not isinstance(t, ocio.MatrixTransform):
            break
        m = np.array(t.getMatrix(), np.float64).reshape(4, 4)[:3, :3]
        off = np.array(t.getOffset(), np.float64)[:3]
        if t.getDirection() == ocio.TRANSFORM_DIR_INVERSE:
            m = np.linalg.inv(m)
            off = -m @ off
        M, o = m @ M, m @ o + off
    if not (np.all(np.isfinite(M)) and abs(np.linalg.det(M)) > 1e-9):
        return np.eye(3), np.zeros(3)
    return M, o


def _run_ocio(cpu_proc, rgb: np.ndarray) -> np.ndarray:
    x = np.ascontiguousarray(np.asarray(rgb, np.float32).reshape(1, -1, 3))
    _apply(cpu_proc, x)
    return x[0].astype(np.float64)


def bake_display_table(proc, form: str = "auto", size_3d: int = 65,
                       vmax: float | None = None, description: str = "",
                       probe: np.ndarray | None = None) -> DisplayTable:
    """Bake OCIO processor ``proc`` (working -> display code values) over [0, vmax]^3.

    ``form``: ``"1d"``, ``"3d"`` or ``"auto"``: a matrix + per-channel 1D table when
    that reproduces OCIO within one 10-bit code value on the probe set (the transform
    is separable after its leading matrix: found by probing, not by the transform's
    name), else the best 3D table of the shapers tried. Every table sample comes from
    OCIO's CPU processor of ``proc``; the self-check is against it too."""
    from .models.display import DISPLAY_LINEAR_MAX
    vmax = float(DISPLAY_LINEAR_MAX if vmax is None else vmax)
    if form not in ("auto", "1d", "3d"):
        raise ValueError(f"table form must be auto, 1d or 3d (got {form!r})")
    cpu = proc.getDefaultCPUProcessor()
    if proc.isNoOp():
        return DisplayTable("identity", np.eye(3), np.zeros(3), 1.0, 0.0, 1.0,
                            np.zeros((0, 3)), "bits", description, vmax)
    if probe is None:
        probe = display_probe_set(50_000, seed=1, vmax=vmax, n_axis=2048)
    probe = np.asarray(probe, np.float32)
    best = None
    if form in ("auto", "1d"):
        M, o = _leading_matrix(proc)
        corners = np.array(np.meshgrid(*[[0.0, vmax]] * 3, indexing="ij")).reshape(3, -1).T
        post = corners @ M.T + o
        eps = SHAPER_EPS_1D
        k = NODES_PER_OCTAVE_1D
        s_lo = math.floor(float(shaper(post.min(), eps)) * k) / k
        s_hi = math.ceil(float(shaper(post.max(), eps)) * k) / k
        t = shaper_inverse(np.linspace(s_lo, s_hi, round((s_hi - s_lo) * k) + 1), eps)
        # the channel curves: OCIO at the RGB that the matrix maps to grey (t, t, t)
        x = np.linalg.solve(M, (t[:, None] - o).T).T
        tab = _run_ocio(cpu, x)
        best = _checked(DisplayTable("1d", M, o, eps, s_lo, s_hi, tab, "bits", description,
                                     vmax), cpu, probe)
        if form == "1d" or best.within_10bit:
            return best
    # 3D: the shapers in turn, then a finer lattice, until within half the bound; a
    # transform hopelessly far from any (ACES output transforms: tens of code values)
    # is not searched further
    for n in (size_3d, (size_3d - 1) * 3 // 2 + 1):
        for eps in SHAPER_EPS_3D:
            s_hi = float(shaper(vmax, eps, "log2"))
            t = shaper_inverse(np.linspace(0.0, s_hi, n), eps, "log2")
            grid = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
            tab = _run_ocio(cpu, grid).reshape(n, n, n, 3)
            cand = _checked(DisplayTable("3d", np.eye(3), np.zeros(3), eps, 0.0, s_hi, tab,
                                         "log2", description, vmax), cpu, probe)
            if best is None or cand.max_error < best.max_error:
                best = cand
            if cand.max_error > 16 * CODE_10BIT or best.max_error < CODE_10BIT / 2:
                break
        if best.max_error > 16 * CODE_10BIT or best.max_error < CODE_10BIT / 2:
            break
    return best


def cached_display_table(proc, form: str = "auto", size_3d: int = 65,
                         description: str = "") -> DisplayTable:
    """:func:`bake_display_table` kept in the user's cache (``display-tables/*.npz``):
    a bake and its self-check cost ~0.1 s of every start. Keyed by OCIO's cache ID of
    the processor (its transforms and LUT files' contents), the OCIO and project
    versions and the bake's constants; a file that cannot be read is baked again."""
    import dataclasses
    import hashlib
    import json
    from . import __version__
    from .models.display import DISPLAY_LINEAR_MAX
    from .resources import cache_write, user_cache_dir
    ident = json.dumps([proc.getCacheID(), form, size_3d, ocio.GetVersion(), __version__,
                        DISPLAY_LINEAR_MAX, SHAPER_EPS_1D, SHAPER_EPS_3D, NODES_PER_OCTAVE_1D,
                        CODE_10BIT])
    path = user_cache_dir() / "display-tables" / \
        f"{hashlib.sha256(ident.encode()).hexdigest()[:32]}.npz"
    fields = [f.name for f in dataclasses.fields(DisplayTable)]
    try:
        with np.load(path, allow_pickle=False) as z:
            kw = {k: (z[k] if z[k].ndim else z[k].item()) for k in fields}
        kw["kind"], kw["shaper"] = str(kw["kind"]), str(kw["shaper"])
        return DisplayTable(**{**kw, "description": description})
    except (OSError, KeyError, ValueError, TypeError):
        pass
    table = bake_display_table(proc, form, size_3d, description=description)
    import io
    buf = io.BytesIO()
    np.savez(buf, **{k: getattr(table, k) for k in fields})
    cache_write(path, buf.getvalue())       # no cache: baked again next time
    return table


def _checked(table: DisplayTable, cpu, probe: np.ndarray) -> DisplayTable:
    import dataclasses
    mx, p999 = table.error_against(cpu, probe)
    return dataclasses.replace(table, max_error=mx, p999_error=p999, probes=len(probe))
