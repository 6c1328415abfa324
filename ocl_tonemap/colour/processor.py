"""The frame's colour pipeline (:class:`ColourPipeline`): working space in, the
display's linear colourspace or its OCIO display/view encoding out, on the CPU or
through a table baked from it on the device (``colour/table.py``)."""

from __future__ import annotations


import numpy as np
import PyOpenColorIO as ocio

from ..models.photometry import RGB709_TO_XYZ, Y_WEIGHTS
from .config import (PLAIN_VIEWS, USE_DISPLAY_NAME, ColourError, InputColour, apply_processor,
                     builtin_config, default_display, default_view, working_space,
                     xyz_to_chromaticities)
from .config import load_config
from .lut_files import cpu_processor, processor
from .table import DISPLAY_ENCODE_MODES, DisplayTable, cached_display_table

def _listed(names) -> str:
    return ", ".join(repr(n) for n in names) or "none"


def check_display_view(cfg: "ocio.Config", display: str | None,
                       view: str | None) -> tuple[str, str]:
    """(display, view) of a run: the ones asked for (``--display``, ``--view``), else the
    config's default display and its un-tone-mapped view. One that the config lacks is
    refused naming itself and listing what the config has."""
    displays = list(cfg.getDisplays())
    name = display or default_display(cfg)
    if name not in displays:
        what = f"--display {name!r}" if display else f"the default display {name!r}"
        raise ColourError(f"{what} is not in the OCIO config{_source(cfg)}; its displays: "
                          f"{_listed(displays)}")
    views = list(cfg.getViews(name))
    v = view or default_view(cfg, name)
    if v not in views:
        raise ColourError(f"--view {v!r} is not a view of display {name!r} in the OCIO "
                          f"config{_source(cfg)}; its views: {_listed(views)}")
    return name, v


def _source(cfg) -> str:
    """`` (NAME)`` of a config that has a name, else nothing."""
    try:
        name = cfg.getName()
    except Exception:  # noqa: BLE001
        name = ""
    return f" ({name})" if name else ""


class ColourPipeline:
    """OCIO processors for one run: input -> working, working -> display."""

    def __init__(self, cfg: "ocio.Config | str | None", display: str | None = None,
                 view: str | None = None):
        """``cfg``: an OCIO Config, or what ``--colorconfig`` takes (a file, an
        ``ocio://`` URI, ``ocl-tonemap``; None: ``$OCIO``, else ``ocio://default``)."""
        if cfg is None or isinstance(cfg, (str, bytes)) or hasattr(cfg, "__fspath__"):
            cfg = load_config(None if cfg is None else str(cfg if not isinstance(cfg, bytes)
                                                               else cfg.decode()))
        self.cfg = cfg
        # what the user named first: a missing display or view names itself and what
        # the config has, before what the config lacks for us (its working space)
        self.display, self.view = check_display_view(cfg, display, view)
        self.working = working_space(cfg)
        self._in_procs: dict[str, object] = {}
        self._out = cpu_processor(cfg, self.working, self.display, self.view,
                                  ocio.TRANSFORM_DIR_FORWARD)

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
            proc = cpu_processor(self.cfg, src_cs, self.working)
            self._in_procs[src_cs] = proc
        apply_processor(proc, pixels)
        return pixels

    def convert_input(self, pixels: np.ndarray, ic: InputColour) -> np.ndarray:
        """Working-space RGB of (H, W, C>=3) float32 ``pixels`` described by ``ic``
        (converted in place where possible; returns the array). Half floats read as
        stored stay half where nothing is converted, else become float32 first."""
        if ic.kind == "working" or (ic.kind == "ocio" and not ic.builtin and
                                    self.cfg.getColorSpace(ic.colorspace).getName()
                                    == self.working):
            return pixels
        if pixels.dtype != np.float32:
            pixels = np.asarray(pixels, np.float32)
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
            proc = cpu_processor(b, ic.colorspace, working_space(b))
            self._in_procs[key] = proc
        apply_processor(proc, pixels)
        return pixels

    def input_transform(self, ic: InputColour):
        """The conversion :meth:`convert_input` makes, as an OCIO GroupTransform (None:
        the input is the working space)."""
        if ic.kind == "working":
            return None
        g = ocio.GroupTransform()
        if ic.kind == "matrix":
            m = np.eye(4)
            m[:3, :3] = np.asarray(ic.matrix, np.float64)
            g.appendTransform(ocio.MatrixTransform(matrix=[float(v) for v in m.reshape(-1)]))
            return g
        if not ic.builtin and self.cfg.getColorSpace(ic.colorspace).getName() == self.working:
            return None
        cfg = builtin_config() if ic.builtin else self.cfg
        return processor(cfg, ic.colorspace, working_space(cfg)).createGroupTransform()

    def _matrix_from_working(self, cs: str) -> np.ndarray | None:
        """The 3x3 matrix working -> ``cs`` when OCIO's transform is linear, else None."""
        try:
            proc = cpu_processor(self.cfg, self.working, cs)
        except Exception:  # noqa: BLE001 -- OCIO's, or a LUT refused: not a candidate
            return None
        probe = np.array([[[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, 0.25, 2.0], [4.0, 8.0, 0.5]]],
                         np.float32)
        apply_processor(proc, probe)
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
                proc = cpu_processor(self.cfg, self.working, name)
                self._in_procs[key] = proc
            apply_processor(proc, out)
        return out

    def output_chromaticities(self, encoded: bool) -> tuple:
        """EXR chromaticities of what is written: the display's primaries (encoded
        output), or those of the linear output colourspace."""
        if encoded:
            return xyz_to_chromaticities(RGB709_TO_XYZ @ self.display_primaries())
        _, M = self.linear_output()
        return xyz_to_chromaticities(RGB709_TO_XYZ @ np.linalg.inv(M))

    def display_primaries(self) -> np.ndarray:
        """(3, 3): column c is the working-space linear RGB of the display's primary c
        (through the inverse display/view transform), scaled so that the columns
        sum to luminance 1. For a BT.709 display this is the identity."""
        proc = cpu_processor(self.cfg, self.working, self.display, self.view,
                             ocio.TRANSFORM_DIR_INVERSE)
        codes = np.array([[[0.5, 0, 0], [0, 0.5, 0], [0, 0, 0.5], [0, 0, 0]]], np.float32)
        apply_processor(proc, codes)
        D = (codes[0, :3] - codes[0, 3]).T.astype(np.float64)
        y = float(Y_WEIGHTS @ D.sum(axis=1))
        if not (np.all(np.isfinite(D)) and y > 0):
            return np.eye(3)
        return D / y

    def encode(self, display_linear: np.ndarray) -> np.ndarray:
        """Display-linear working-space RGB -> display encoding (new array)."""
        out = np.array(display_linear, dtype=np.float32, copy=True, order="C")
        apply_processor(self._out, out)
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
            proc = processor(self.cfg, self.working, self.display, self.view,
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
                # lazy: the device modules only for a device table
                from ..backends.opencl.display import DeviceDisplayTable
                self.device_table = DeviceDisplayTable(table, device=device)
        except Exception as exc:  # noqa: BLE001 -- auto: OCIO is always there
            if mode == "table":
                raise
            self.display_encode_note = (f"display encoding: OCIO CPU processor (no device "
                                        f"table: {exc})")
            return self.display_encode_note
        self.display_encode_note = "display encoding: " + table.describe()
        return self.display_encode_note

    def device_output_encoding(self, bits: int, runtime):
        """:meth:`encode_fast` (``bits`` as there) as a ``DeviceOutputEncoding`` for an
        operator whose output is on ``runtime``'s device (an OpenCL runtime), so that the
        table runs there and only code values come back; None where :meth:`encode_fast`
        uses OCIO, or the table is in another context."""
        table = self.device_table
        if table is None or runtime is None or \
                runtime.context != table.rt.context:
            return None
        bits = 8 if bits is True else int(bits or 0)
        cache = self.__dict__.setdefault("_device_encodings", {})
        enc = cache.get(bits)
        if enc is None or enc.table is not table:
            # lazy: the device modules only for a device table
            from ..backends.opencl.display import DeviceOutputEncoding
            cache[bits] = enc = DeviceOutputEncoding(table, bits)
        return enc

    def encode_fast(self, display_linear: np.ndarray, bits: int = 0) -> np.ndarray:
        """:meth:`encode` through the device table chosen by :meth:`set_display_encode` (new
        array; RGB encoded, a 4th channel kept), or through OCIO when none was chosen.
        ``bits`` 8 or 16: integer code values quantised on the device as OIIO quantises
        them when it writes, where a device table encodes (else float code values)."""
        table = self.device_table
        if table is None:
            return self.encode(display_linear)
        if bits and display_linear.shape[-1] in (3, 4):
            return table.encode(display_linear, bits=bits)
        return table.encode(display_linear)
